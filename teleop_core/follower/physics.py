"""The physics stage of the force estimator: eq. 1 solved for the proximal force.

    K_t I_q = J theta_dd + b theta_d + tau_c sgn(theta_d) + r F        (eq. 1)

so that

    F_physics = (K_t I_q - J theta_dd - b theta_d - tau_c sgn(theta_d)) / r + F_0

with an offset F_0 for the load cell's zero. sgn is smoothed to tanh(theta_d / w_s):
the measured speed of a wheel at rest dithers around zero, and a hard sign would turn
that dither into +-tau_c/r of force noise (and the EKF needs a derivative).

Only ratios to r can be identified from force data, so r is taken as known (the
wheel's measured radius) and K_t, J, b, tau_c and F_0 are fitted by bounded linear
least squares (`scipy.optimize.lsq_linear`; J, b, tau_c >= 0, K_t > 0).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from teleop_core._jit import njit
from teleop_core._typing import Float1D, Float2D
from teleop_core.errors import TeleopInputError
from teleop_core.follower.params import FollowerPlantParams
from teleop_core.follower.recording import FollowerRecording

# `PhysicsParams.vector()` layout, as `force_at` and `gradient_at` read it
PV_KT, PV_J, PV_B, PV_TC, PV_R, PV_F0, PV_W = range(7)
PV_SIZE = 7
# `regressors` columns: K_t, J, b, tau_c (each over r) and F_0
RC_KT, RC_J, RC_B, RC_TC, RC_F0 = range(5)
REGRESSORS = 5


@dataclass(frozen=True)
class PhysicsParams:
    """Parameters of eq. 1 as fitted (or assumed); SI units."""

    torque_constant_n_m_per_a: float = 0.043
    """K_t, torque per q-axis ampere."""
    inertia_kg_m2: float = 5.0e-6
    """J_eq."""
    viscous_damping_n_m_s_per_rad: float = 2.0e-5
    """b."""
    coulomb_friction_n_m: float = 0.8e-3
    """tau_c."""
    wheel_radius_m: float = FollowerPlantParams.wheel_radius_m
    """r, not fitted (the drive's wheel)."""
    offset_n: float = 0.0
    """F_0, the reference sensor's zero as seen by the model."""
    sign_speed_rad_s: float = 0.3
    """w_s of the smoothed sign tanh(theta_d / w_s); a setting, not fitted."""

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not math.isfinite(value):
                raise TeleopInputError(
                    f"PhysicsParams.{name} = {value!r}; expected a finite number"
                )
        if self.wheel_radius_m <= 0 or self.sign_speed_rad_s <= 0:
            raise TeleopInputError(
                f"wheel_radius_m {self.wheel_radius_m!r} and sign_speed_rad_s "
                f"{self.sign_speed_rad_s!r} must be > 0"
            )

    def force(self, iq: Float1D, omega: Float1D, alpha: Float1D) -> Float1D:
        """F_physics, N, for arrays (or floats) of current [A], speed [rad/s], accel [rad/s^2]."""
        # F = (K_t I_q - J theta_dd - b theta_d - tau_c sgn(theta_d)) / r + F_0
        torque = (
            self.torque_constant_n_m_per_a * iq
            - self.inertia_kg_m2 * alpha
            - self.viscous_damping_n_m_s_per_rad * omega
            - self.coulomb_friction_n_m * np.tanh(omega / self.sign_speed_rad_s)
        )
        return torque / self.wheel_radius_m + self.offset_n

    def vector(self) -> np.ndarray:
        """The parameters as `force_at` and `gradient_at` take them."""
        pv = np.empty(PV_SIZE)
        pv[PV_KT], pv[PV_J], pv[PV_B] = (
            self.torque_constant_n_m_per_a,
            self.inertia_kg_m2,
            self.viscous_damping_n_m_s_per_rad,
        )
        pv[PV_TC], pv[PV_R] = self.coulomb_friction_n_m, self.wheel_radius_m
        pv[PV_F0], pv[PV_W] = self.offset_n, self.sign_speed_rad_s
        return pv

    def force_gradient(self, omega: float, dt_s: float) -> tuple[float, float]:
        """dF/dI_q and dF/dtheta_d at `omega`, the latter through alpha's backward difference."""
        g_i, g_w = gradient_at(self.vector(), float(omega), float(dt_s))
        return float(g_i), float(g_w)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def regressors(omega: Float1D, iq: Float1D, alpha: Float1D, sign_speed: float) -> Float2D:
    """Columns multiplying (K_t, J, b, tau_c)/r and F_0 in eq. 1 solved for F."""
    return np.column_stack([iq, -alpha, -omega, -np.tanh(omega / sign_speed), np.ones_like(iq)])


def fit_physics(
    recording: FollowerRecording,
    *,
    wheel_radius_m: float = PhysicsParams.wheel_radius_m,
    sign_speed_rad_s: float = PhysicsParams.sign_speed_rad_s,
    mask: np.ndarray | None = None,
) -> PhysicsParams:
    """Fit eq. 1 to a recording by bounded linear least squares.

    Parameters
    ----------
    recording
        Bench recording with `f_ref`.
    wheel_radius_m
        Known wheel radius r, m.
    sign_speed_rad_s
        Smoothing speed of sgn, rad/s.
    mask : (n,) bool array, optional
        Samples to fit on (e.g. the training block); all when omitted.
    """
    use = np.ones(len(recording), bool) if mask is None else np.asarray(mask, bool)
    A = regressors(recording.omega[use], recording.iq[use], recording.alpha[use], sign_speed_rad_s)
    y = recording.f_ref[use]
    # Scale columns so the solver sees comparable magnitudes (alpha is ~1e3 x iq).
    scale = np.maximum(np.abs(A).max(axis=0), 1e-12)
    lower = np.array([1e-9, 0.0, 0.0, 0.0, -np.inf])
    from scipy.optimize import lsq_linear  # only when fitting (0.5-0.7 s to import)

    result = lsq_linear(A / scale, y, bounds=(lower * scale, np.full(REGRESSORS, np.inf)))
    return from_coefficients(result.x / scale, wheel_radius_m, sign_speed_rad_s)


def from_coefficients(
    beta: Float1D,
    wheel_radius_m: float,
    sign_speed_rad_s: float = PhysicsParams.sign_speed_rad_s,
) -> PhysicsParams:
    """Eq. 1's parameters from the coefficients of `regressors`' five columns (N per unit)."""
    r = wheel_radius_m
    return PhysicsParams(
        torque_constant_n_m_per_a=float(beta[RC_KT] * r),
        inertia_kg_m2=float(beta[RC_J] * r),
        viscous_damping_n_m_s_per_rad=float(beta[RC_B] * r),
        coulomb_friction_n_m=float(beta[RC_TC] * r),
        wheel_radius_m=r,
        offset_n=float(beta[RC_F0]),
        sign_speed_rad_s=sign_speed_rad_s,
    )


@njit(cache=True)
def force_at(pv: np.ndarray, iq: float, omega: float, alpha: float) -> float:  # pragma: no cover
    """Eq. 1 for one sample, `pv` = `PhysicsParams.vector()` (the streaming path)."""
    # F = (K_t I_q - J theta_dd - b theta_d - tau_c tanh(theta_d / w)) / r + F_0   (eq. 1)
    torque = (
        pv[PV_KT] * iq
        - pv[PV_J] * alpha
        - pv[PV_B] * omega
        - pv[PV_TC] * math.tanh(omega / pv[PV_W])
    )
    return torque / pv[PV_R] + pv[PV_F0]


@njit(cache=True)
def gradient_at(pv: np.ndarray, omega: float, dt_s: float) -> tuple[float, float]:
    """dF/dI_q and dF/dtheta_d (`PhysicsParams.force_gradient`)."""
    # dF/dtheta_d = -(b + tau_c sech^2(theta_d / w) / w + J / dt) / r, since
    # theta_dd = (theta_d - theta_d,prev) / dt
    r = pv[PV_R]
    sech2 = 1.0 / math.cosh(omega / pv[PV_W]) ** 2
    d_omega = -(pv[PV_B] + pv[PV_TC] * sech2 / pv[PV_W] + pv[PV_J] / dt_s) / r
    return pv[PV_KT] / r, d_omega
