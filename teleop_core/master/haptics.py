"""The dial's rendering laws ([endovascular], III-B): eqs. 5, 7-9 and the inverse map Psi (eq. 10).

Each law is a scalar numba function so that the closed loop's compiled kernel
(`teleop_core.loop.kernel`) calls exactly the code the tests exercise; `InverseMap`
wraps Psi with its branch memory for use from Python.

Sign conventions: a positive dial angle is clockwise and advances the guidewire (eq. 5);
a positive insertion force resists advancing. The haptic torque therefore opposes the
dial's deflection: tau_h = -G_h F (eq. 7 gives the magnitude, G_h |F|).

Psi (eq. 10): the published polynomials (eqs. 14-15) give the gauge force for a current
magnitude in mA on the loading and unloading branch. "Loading" is taken as the torque's
magnitude growing, sgn(tau) sgn(d tau/dt) > 0, so the map is odd in tau (the motor is
taken as symmetric; the paper calibrates one direction); when d tau/dt = 0 the previous
branch is kept. The quadratic is inverted in closed form on its rising side.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from teleop_core._jit import njit
from teleop_core.master.params import CalibrationPolynomials

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

LOADING = 1.0
UNLOADING = -1.0


@njit(cache=True)
def rate_command(theta_m_rad: float, speed_gain_m_s_per_rad: float) -> float:
    """Guidewire speed command, m/s."""
    # v_gw = k_v theta_m   (eq. 5)
    return speed_gain_m_s_per_rad * theta_m_rad


@njit(cache=True)
def haptic_torque(
    force_n: float, gain_n_m_per_n: float, deadband_n: float, saturation_n_m: float
) -> float:
    """Haptic torque for an estimated insertion force, N m (0 for a non-finite force)."""
    if not math.isfinite(force_n):
        return 0.0
    # deadband: |F| <= F_db renders nothing; beyond it the torque grows from zero
    excess = abs(force_n) - deadband_n
    if excess <= 0.0:
        return 0.0
    # tau_h = G_h F   (eq. 7), saturated, opposing the advancing direction
    tau = min(gain_n_m_per_n * excess, saturation_n_m)
    return -tau if force_n > 0.0 else tau


@njit(cache=True)
def return_torque(
    theta_rad: float,
    omega_rad_s: float,
    spring_n_m_per_rad: float,
    damper_n_m_s_per_rad: float,
    reference_rad: float,
) -> float:
    """Virtual spring-damper torque, N m."""
    # tau_return = -K_s (theta_m - theta_ref) - B_s theta_m_dot   (eq. 8)
    return -spring_n_m_per_rad * (theta_rad - reference_rad) - damper_n_m_s_per_rad * omega_rad_s


@njit(cache=True)
def _invert_rising(a: float, b: float, c: float, force_n: float) -> float:
    """The current (mA) on the rising side of a i^2 + b i + c = F."""
    if a == 0.0:
        return (force_n - c) / b
    # a i^2 + b i + (c - F) = 0, root nearest zero for a < 0 (rising side below the vertex)
    disc = b * b - 4.0 * a * (c - force_n)
    if disc < 0.0:
        disc = 0.0
    return (-b + math.sqrt(disc)) / (2.0 * a)


@njit(cache=True)
def psi(
    tau_n_m: float,
    tau_prev_n_m: float,
    branch_prev: float,
    poly: NDArray[np.float64],
    lever_arm_m: float,
    max_current_ma: float,
) -> tuple[float, float]:
    """Eq. 10: (current command in mA, branch used).

    `poly` holds the loading (a, b, c) then the unloading (a, b, c) coefficients.
    """
    if not math.isfinite(tau_n_m):
        return 0.0, branch_prev
    # branch from sgn(tau) sgn(d tau/dt): magnitude growing -> loading (eq. 14), else eq. 15
    trend = tau_n_m * (tau_n_m - tau_prev_n_m) if math.isfinite(tau_prev_n_m) else 0.0
    branch = branch_prev
    if trend > 0.0:
        branch = LOADING
    elif trend < 0.0:
        branch = UNLOADING
    k = 0 if branch == LOADING else 3
    a, b, c = poly[k], poly[k + 1], poly[k + 2]
    force = abs(tau_n_m) / lever_arm_m
    if force <= c:  # below the fit's intercept: nothing to render
        return 0.0, branch
    f_max = a * max_current_ma * max_current_ma + b * max_current_ma + c
    i_ma = max_current_ma if force >= f_max else _invert_rising(a, b, c, force)
    i_ma = min(max(i_ma, 0.0), max_current_ma)
    return (i_ma if tau_n_m > 0.0 else -i_ma), branch


class InverseMap:
    """Psi with its memory (previous torque and branch); returns the current in A.

    >>> m = InverseMap()
    >>> round(m(0.025 * 1.0) * 1000, 3)  # 1 N at the 25 mm lever, loading: eq. 14 inverted
    1.474
    """

    def __init__(self, polynomials: CalibrationPolynomials | None = None) -> None:
        # lazy: numpy costs 67 ms at start-up
        import numpy as np

        self.polynomials = polynomials or CalibrationPolynomials()
        p = self.polynomials
        self._poly = np.array([*p.loading, *p.unloading], dtype=np.float64)
        self.tau_prev_n_m = 0.0
        self.branch = LOADING

    def __call__(self, tau_n_m: float) -> float:
        """Current command (A) for a requested dial torque (N m)."""
        p = self.polynomials
        i_ma, self.branch = psi(
            float(tau_n_m),
            self.tau_prev_n_m,
            self.branch,
            self._poly,
            p.lever_arm_m,
            p.max_current_ma,
        )
        if math.isfinite(tau_n_m):
            self.tau_prev_n_m = float(tau_n_m)
        return i_ma / 1000.0  # mA -> A at the boundary
