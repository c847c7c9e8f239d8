"""Parameters of the simulated haptic dial and its rendering ([endovascular], III-B, IV-D).

SI units in the field names; mA only for the calibration polynomials, whose published
form (eqs. 14-15) takes the current in mA. Each field cites its equation or says
"assumption" where the paper is silent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from teleop_core.errors import TeleopInputError
from teleop_core.validation import require_nonnegative, require_positive


@dataclass(frozen=True)
class CalibrationPolynomials:
    """Current-to-force characteristic of the dial's PMSM on the calibration lever.

    F(i) = a i^2 + b i + c with i in mA and F in N (eqs. 14-15); the force is what the
    lever presses on the gauge, so the dial torque is `lever_arm_m` * F.
    """

    loading: tuple[float, float, float] = (-0.023155, 0.725796, -0.019272)
    """(a, b, c) of F_load, eq. 14 (current magnitude increasing)."""
    unloading: tuple[float, float, float] = (-0.043098, 0.743892, 0.022228)
    """(a, b, c) of F_unload, eq. 15 (current magnitude decreasing)."""
    max_current_ma: float = 4.0
    """Upper end of the calibrated range, mA; assumption: both fits rise monotonically
    up to 8.6 mA (eq. 15's vertex), and below 4 mA the two differ by at most 0.2 N, the
    "small hysteresis loop" the paper reports (IV-D)."""
    lever_arm_m: float = 0.025
    """Lever from the dial axis to the force gauge (Fig. 10(a)); assumption."""

    def __post_init__(self) -> None:
        require_positive(self, "max_current_ma", "lever_arm_m")
        for name in ("loading", "unloading"):
            a, b, _ = getattr(self, name)
            if b <= 0 or (a < 0 and -b / (2 * a) < self.max_current_ma):
                raise TeleopInputError(
                    f"{name} polynomial {getattr(self, name)} does not rise over "
                    f"0..{self.max_current_ma} mA; expected a monotonic calibrated range"
                )

    def force_n(self, current_ma: float, branch: str) -> float:
        """F on the `branch` ("loading" or "unloading") at `current_ma` (>= 0), N."""
        a, b, c = getattr(self, branch)
        return a * current_ma * current_ma + b * current_ma + c


@dataclass(frozen=True)
class DialParams:
    """The dial's mechanics (eq. 6) and its motor's current response."""

    inertia_kg_m2: float = 6.0e-6
    """J_m, rotor of a 2804 gimbal motor plus a 40 mm aluminium knob (eq. 6); assumption."""
    viscous_damping_n_m_s_per_rad: float = 1.0e-5
    """B_m (eq. 6); assumption."""
    static_friction_n_m: float = 4.0e-4
    """Breakaway torque of the bearings (eq. 6's static friction); assumption. With K_s
    it sets the band around centre where a released dial may stop: ts / K_s = 0.013 rad,
    0.7 mm/s of guidewire drift at k_v."""
    coulomb_friction_n_m: float = 3.0e-4
    """Sliding friction (eq. 6's Coulomb friction); assumption."""
    current_time_constant_s: float = 0.001
    """Closed current loop of the ESP32 (SimpleFOC) as a first-order lag; assumption
    (~160 Hz, typical of a gimbal motor's current loop)."""
    hysteresis_width_ma: float = 0.25
    """Current change over which the output moves from one calibrated branch to the
    other after a reversal (a Dahl-type transition between eqs. 14 and 15); assumption."""
    gauge_noise_n: float = 0.01
    """Standard deviation of the force gauge used to calibrate the dial; assumption."""
    gauge_time_constant_s: float = 0.0152
    """The calibration bench's lever and force gauge as a first-order low-pass (the
    gauge's own filtering and the lever's compliance); assumption, set so that the bench
    measures the paper's ~8 Hz -2 dB bandwidth (IV-D, Fig. 10(c)) together with the
    current loop. It shapes what the bench measures, not what the hand feels: the
    paper's < 5 ms force latency rules out an 8 Hz lag in the rendering itself."""
    polynomials: CalibrationPolynomials = field(default_factory=CalibrationPolynomials)

    def __post_init__(self) -> None:
        require_positive(
            self,
            "inertia_kg_m2",
            "current_time_constant_s",
            "hysteresis_width_ma",
            "gauge_time_constant_s",
        )
        require_nonnegative(
            self,
            "viscous_damping_n_m_s_per_rad",
            "static_friction_n_m",
            "coulomb_friction_n_m",
            "gauge_noise_n",
        )
        if self.coulomb_friction_n_m > self.static_friction_n_m:
            raise TeleopInputError(
                f"coulomb_friction_n_m {self.coulomb_friction_n_m} exceeds static_friction_n_m "
                f"{self.static_friction_n_m}; expected breakaway >= sliding friction"
            )


@dataclass(frozen=True)
class HapticParams:
    """Rate control and haptic rendering on the dial (eqs. 5, 7, 8)."""

    speed_gain_m_s_per_rad: float = 0.05
    """k_v, guidewire speed per dial angle (eq. 5); assumption: 1 rad gives 50 mm/s,
    5 rad/s at the 10 mm friction wheel, inside the estimator's training range."""
    haptic_gain_n_m_per_n: float = 0.02
    """G_h, dial torque per newton of estimated insertion force (eq. 7); assumption."""
    deadband_n: float = 0.05
    """Forces below this magnitude render no torque (eq. 7's deadband); assumption: the
    estimator's noise at rest, below the 0.192 N JND."""
    saturation_n_m: float = 0.05
    """Largest haptic torque (eq. 7's saturation); assumption, inside the calibrated range."""
    spring_n_m_per_rad: float = 0.03
    """K_s, virtual return spring (eq. 8); assumption."""
    damper_n_m_s_per_rad: float = 2.0e-3
    """B_s, virtual damper (eq. 8); assumption. Rendered through the current loop's lag,
    a released dial obeys J tau_i s^3 + J s^2 + B_s s + K_s = 0, unstable without the
    damper (Routh-Hurwitz: stable only for B_s > tau_i K_s); 2e-3 returns it to centre
    in about 0.3 s without overshoot (Fig. 3(c)-(d))."""
    reference_angle_rad: float = 0.0
    """theta_ref, the dial's neutral angle (eq. 8)."""
    haptics_on: bool = True
    """HV (True) renders eq. 7; VO (False) renders only the return spring-damper."""

    def __post_init__(self) -> None:
        require_positive(self, "speed_gain_m_s_per_rad", "spring_n_m_per_rad")
        require_nonnegative(
            self, "haptic_gain_n_m_per_n", "deadband_n", "saturation_n_m", "damper_n_m_s_per_rad"
        )
        if not math.isfinite(self.reference_angle_rad):
            raise TeleopInputError(
                f"reference_angle_rad = {self.reference_angle_rad!r}; expected a finite angle"
            )
