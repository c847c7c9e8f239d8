"""The EKF stage: fuses the physics and hybrid force estimates with what is known of the noise.

State x = [F_physics, F_GRU*] (N), measurement z = [I_q, theta_d] ([endovascular], III-A-4).
The forces are not measured; they reach the filter through the two estimators, which
are functions of z: y = [F_physics(z), F_GRU*(z window)]. The filter is "extended"
because the measurement noise is mapped through those non-linear functions at every
step: R_k = G_k R_z G_k' with G_k the gradient of eq. 1's force with respect to
[I_q, theta_d] at the current speed (the smoothed Coulomb term and theta_dd's
backward difference make it speed- and rate-dependent), plus each estimator's own
model error (the physics fit's and the GRU's residual variance on training data). R_z,
the variance of I_q and theta_d, comes from the recording while the wheel is at rest
([endovascular], IV-C). Both forces follow random walks with process noise Q (settable; by
default tuned like the paper's, see `training.tune_process_noise`).

Written by hand rather than with filterpy (which the paper used): two states and a
closed-form 2x2 inverse, compiled with numba, cost about a microsecond per update,
and the update runs inside the closed loop's compiled kernel.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from teleop_core._jit import njit
from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError
from teleop_core.follower.physics import PhysicsParams, gradient_at


@dataclass(frozen=True)
class EkfSettings:
    """Noise covariances of the force EKF (diagonal)."""

    q_physics_n2: float = 4e-3
    """Process noise of F_physics per step, N^2."""
    q_hybrid_n2: float = 4e-3
    """Process noise of F_GRU* per step, N^2."""
    r_iq_a2: float = 3.6e-5
    """Variance of the measured I_q at rest, A^2."""
    r_omega_rad2_s2: float = 1e-3
    """Variance of the measured theta_d at rest, (rad/s)^2."""
    r_physics_model_n2: float = 4e-3
    """Variance of eq. 1's own error (training residual), N^2."""
    r_gru_n2: float = 1e-3
    """Variance of the hybrid estimate's own error (GRU validation), N^2."""
    passthrough: bool = False
    """Pass F_GRU* through unfiltered: set by training where the filter did not improve
    the hybrid estimate on the validation blocks."""

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if name == "passthrough":
                if not isinstance(value, bool):
                    raise TeleopInputError(f"EkfSettings.passthrough = {value!r}; expected a bool")
            elif not (math.isfinite(value) and value > 0):
                raise TeleopInputError(f"EkfSettings.{name} = {value!r}; expected > 0")

    def to_dict(self) -> dict[str, float | bool]:
        return asdict(self)


class ForceEkf:
    """Two-state EKF over [F_physics, F_GRU*]; call `update` once per estimate.

    The state lives in one array (`state`: initialised flag, x, P as p11, p12, p22) and
    the step is a numba function, `ekf_update`, which the loop kernel calls too.
    """

    def __init__(self, settings: EkfSettings, physics: PhysicsParams, dt_s: float) -> None:
        self.settings = settings
        self.physics = physics
        self.dt_s = dt_s
        self.state = np.zeros(EKF_STATE_SIZE)
        self._sv = settings_vector(settings)
        self._pv = physics.vector()

    def update(self, f_physics: float, f_hybrid: float, omega: float) -> float:
        """Filter one step; return the final force F*_Final (N)."""
        return ekf_update(self.state, self._sv, self._pv, self.dt_s, f_physics, f_hybrid, omega)


# state: initialised flag, x = (F_physics, F_GRU*), P as p11, p12, p22
EK_INIT, EK_X1, EK_X2, EK_P11, EK_P12, EK_P22 = range(6)
EKF_STATE_SIZE = 6
# settings vector (`settings_vector`): process noise Q, sensor noise R_z, model noise, flag
SV_Q_PHYSICS, SV_Q_HYBRID, SV_R_IQ, SV_R_OMEGA, SV_R_MODEL, SV_R_GRU, SV_PASSTHROUGH = range(7)
SETTINGS_SIZE = 7


def settings_vector(s: EkfSettings) -> np.ndarray:
    sv = np.empty(SETTINGS_SIZE)
    sv[SV_Q_PHYSICS], sv[SV_Q_HYBRID] = s.q_physics_n2, s.q_hybrid_n2
    sv[SV_R_IQ], sv[SV_R_OMEGA] = s.r_iq_a2, s.r_omega_rad2_s2
    sv[SV_R_MODEL], sv[SV_R_GRU] = s.r_physics_model_n2, s.r_gru_n2
    sv[SV_PASSTHROUGH] = 1.0 if s.passthrough else 0.0
    return sv


@njit(cache=True)
def ekf_update(
    state: np.ndarray,
    sv: np.ndarray,
    pv: np.ndarray,
    dt_s: float,
    f_physics: float,
    f_hybrid: float,
    omega: float,
) -> float:  # pragma: no cover - compiled; exercised through ForceEkf
    """One EKF step on `state` (flag, x1, x2, p11, p12, p22); returns F*_Final (N).

    With the pass-through flag (sv[SV_PASSTHROUGH]) set, F*_Final is F_GRU* itself."""
    if sv[SV_PASSTHROUGH] != 0.0:
        return f_hybrid
    g_i, g_w = gradient_at(pv, omega, dt_s)
    # R = G R_z G' + diag(r_model, r_gru); both rows of G are eq. 1's gradient
    common = g_i * g_i * sv[SV_R_IQ] + g_w * g_w * sv[SV_R_OMEGA]
    r11, r12, r22 = common + sv[SV_R_MODEL], common, common + sv[SV_R_GRU]
    if state[EK_INIT] == 0.0:
        state[EK_INIT] = 1.0
        state[EK_X1], state[EK_X2] = f_physics, f_hybrid
        state[EK_P11], state[EK_P12], state[EK_P22] = r11, r12, r22
        return f_hybrid
    # Predict: x = x (random walk); P = P + Q
    p11 = state[EK_P11] + sv[SV_Q_PHYSICS]
    p12 = state[EK_P12]
    p22 = state[EK_P22] + sv[SV_Q_HYBRID]
    # S = H P H' + R with H = I
    s11, s12, s22 = p11 + r11, p12 + r12, p22 + r22
    det = s11 * s22 - s12 * s12
    i11, i12, i22 = s22 / det, -s12 / det, s11 / det
    # K = P S^-1
    k11 = p11 * i11 + p12 * i12
    k12 = p11 * i12 + p12 * i22
    k21 = p12 * i11 + p22 * i12
    k22 = p12 * i12 + p22 * i22
    # y = z - h(x); x = x + K y
    y1 = f_physics - state[EK_X1]
    y2 = f_hybrid - state[EK_X2]
    x1 = state[EK_X1] + k11 * y1 + k12 * y2
    x2 = state[EK_X2] + k21 * y1 + k22 * y2
    state[EK_X1], state[EK_X2] = x1, x2
    # P = (I - K) P
    state[EK_P11] = (1 - k11) * p11 - k12 * p12
    state[EK_P12] = (1 - k11) * p12 - k12 * p22
    state[EK_P22] = -k21 * p12 + (1 - k22) * p22
    return x2


def filter_forces(
    settings: EkfSettings,
    physics: PhysicsParams,
    dt_s: float,
    f_physics: Float1D,
    f_hybrid: Float1D,
    omega: Float1D,
) -> Float1D:
    """Run the EKF over whole arrays (the same updates as one at a time)."""
    ekf = ForceEkf(settings, physics, dt_s)
    return np.array(
        [
            ekf.update(a, b, w)
            for a, b, w in zip(f_physics.tolist(), f_hybrid.tolist(), omega.tolist(), strict=True)
        ]
    )


def rest_variances(
    iq: Float1D, omega: Float1D, alpha: Float1D, min_samples: int = 20
) -> tuple[float, float] | None:
    """Noise variances of I_q and theta_d while the wheel is at rest, or None if it never is.

    At rest the load may still change slowly, so the noise is taken from first
    differences: var(noise) = var(diff(x)) / 2 for white noise.
    """
    rest = (np.abs(omega) < 0.05) & (np.abs(alpha) < 5.0)
    both = rest[1:] & rest[:-1]
    if both.sum() < min_samples:
        return None
    d_iq = np.diff(iq)[both]
    d_w = np.diff(omega)[both]
    return float(np.var(d_iq) / 2), max(float(np.var(d_w) / 2), 1e-6)
