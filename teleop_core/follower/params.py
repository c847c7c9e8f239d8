"""Parameters of the simulated friction-wheel guidewire drive ([endovascular], III-A, IV-A).

Every field is SI with the unit in its name and cites its source: a paper equation or
table, or "assumption" where the paper is silent (DESIGN.md lists the assumed 2804
gimbal motor figures). The plant deliberately carries effects that eq. 1 lacks
(Stribeck friction, stiction, torque-constant saturation, cogging) so that the GRU
residual compensator has something real to learn; `FollowerPlantParams.ideal()` turns
them off, which leaves exactly the eq. 1-2 system.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from teleop_core.errors import TeleopInputError
from teleop_core.validation import require_nonnegative, require_positive


@dataclass(frozen=True)
class FollowerPlantParams:
    """Mechanics and electrics of the PMSM friction-wheel drive (eqs. 1-2 plus what they omit)."""

    torque_constant_n_m_per_a: float = 0.043
    """K_t, T_m = K_t I_q (eq. 1); assumption: 2804 gimbal motor (DESIGN.md)."""
    pole_pairs: int = 7
    """Electrical/mechanical speed ratio; assumption: 2804 gimbal motor."""
    wheel_radius_m: float = 0.010
    """r, friction-wheel radius turning force into torque (eq. 1); assumption."""
    inertia_kg_m2: float = 5.0e-6
    """J_eq, rotor + friction wheel (eq. 1-2); assumption (outer rotor of ~20 g at 14 mm)."""
    viscous_damping_n_m_s_per_rad: float = 2.0e-5
    """b, viscous friction (eq. 1-2); assumption."""
    coulomb_friction_n_m: float = 0.8e-3
    """tau_c, Coulomb friction while sliding (eq. 1-2); assumption (0.08 N at the wheel)."""
    static_friction_n_m: float = 1.1e-3
    """Breakaway (stiction) torque, >= tau_c; assumption. Not in eq. 1."""
    stribeck_speed_rad_s: float = 0.6
    """Speed over which friction falls from static to Coulomb; assumption. Not in eq. 1."""
    torque_saturation_per_a2: float = 0.15
    """K_t(i) = K_t (1 - k i^2): magnetic saturation at high current; assumption. Not in eq. 1."""
    quadratic_drag_n_m_s2_per_rad2: float = 1.5e-5
    """c in c theta_d |theta_d|: drag of the pinched guidewire in its tube growing faster
    than linearly with speed; assumption. Not in eq. 1."""
    retract_friction_ratio: float = 1.4
    """Coulomb and static friction when withdrawing over those when advancing (the pinch
    wheel's asymmetric preload); assumption. Not in eq. 1."""
    cogging_torque_n_m: float = 0.0
    """Amplitude of the cogging torque, periodic in rotor angle; assumption (0: gimbal motor)."""
    cogging_periods_per_rev: int = 84
    """Cogging periods per revolution, lcm(12 slots, 14 poles); assumption."""
    phase_resistance_ohm: float = 10.0
    """q-axis resistance; assumption (gimbal motors wind for high resistance)."""
    phase_inductance_h: float = 2.0e-3
    """q-axis inductance; assumption."""
    voltage_limit_v: float = 6.9
    """Largest q-axis voltage, 12 V supply under SVPWM (12/sqrt 3); assumption (DRV8313)."""

    def __post_init__(self) -> None:
        require_positive(
            self,
            "torque_constant_n_m_per_a",
            "pole_pairs",
            "wheel_radius_m",
            "inertia_kg_m2",
            "stribeck_speed_rad_s",
            "phase_resistance_ohm",
            "phase_inductance_h",
            "voltage_limit_v",
            "cogging_periods_per_rev",
        )
        require_nonnegative(
            self,
            "viscous_damping_n_m_s_per_rad",
            "coulomb_friction_n_m",
            "static_friction_n_m",
            "torque_saturation_per_a2",
            "cogging_torque_n_m",
            "quadratic_drag_n_m_s2_per_rad2",
            "retract_friction_ratio",
        )
        if self.retract_friction_ratio <= 0:
            raise TeleopInputError(
                f"retract_friction_ratio = {self.retract_friction_ratio!r}; expected > 0"
            )
        if self.static_friction_n_m < self.coulomb_friction_n_m:
            raise TeleopInputError(
                f"static_friction_n_m = {self.static_friction_n_m!r} is below "
                f"coulomb_friction_n_m = {self.coulomb_friction_n_m!r}; expected >="
            )

    def ideal(self) -> FollowerPlantParams:
        """The same drive with only what eq. 1 models: Coulomb and viscous friction."""
        return replace(
            self,
            static_friction_n_m=self.coulomb_friction_n_m,
            torque_saturation_per_a2=0.0,
            cogging_torque_n_m=0.0,
            quadratic_drag_n_m_s2_per_rad2=0.0,
            retract_friction_ratio=1.0,
        )


@dataclass(frozen=True)
class FollowerControlParams:
    """FOC current loop and speed loop as run on the ESP32 unit ([endovascular], IV-A)."""

    current_loop_rate_hz: float = 10_000.0
    """FOC current loop rate; assumption (SimpleFOC on ESP32)."""
    current_loop_bandwidth_hz: float = 800.0
    """Closed-loop bandwidth the current PI is tuned for; assumption."""
    speed_loop_rate_hz: float = 1_000.0
    """Speed loop and device-physics rate (DESIGN.md: 1 kHz device physics)."""
    speed_kp_a_s_per_rad: float = 0.018
    """Speed PI proportional gain; assumption (about 25 Hz crossover with J above)."""
    speed_ki_a_per_rad: float = 0.6
    """Speed PI integral gain; assumption."""
    velocity_filter_s: float = 0.002
    """Time constant of the low-pass on the differentiated encoder angle; assumption."""
    current_limit_a: float = 0.7
    """Largest commanded q-axis current; assumption (what 6.9 V drives through 10 ohm)."""

    def __post_init__(self) -> None:
        require_positive(self, *(f.name for f in fields(self)))


@dataclass(frozen=True)
class FollowerSensorParams:
    """The paper's sensor chain ([endovascular], IV-A) and the bench's reference instruments."""

    encoder_counts_per_rev: int = 4096
    """AS5600 magnetic encoder, 12 bit ([endovascular], IV-A)."""
    current_filter_s: float = 0.005
    """Low-pass of the firmware's measured q-axis current; assumption (SimpleFOC default)."""
    current_noise_a: float = 0.006
    """INA240 + ESP32 ADC noise on each acquired I_q sample, standard deviation; assumption."""
    acquisition_rate_hz: float = 100.0
    """Hardware data acquisition rate ([endovascular], IV-A)."""
    estimation_rate_hz: float = 50.0
    """Rate of the estimation pipeline ([endovascular], IV-A)."""
    force_sensor_noise_n: float = 0.008
    """DYLY-109 reference load cell noise, standard deviation; assumption."""
    reference_encoder_counts_per_rev: int = 8000
    """E6B2-CWZ6C, 2000 P/R read in quadrature ([endovascular], IV-B)."""

    def __post_init__(self) -> None:
        require_positive(
            self,
            "encoder_counts_per_rev",
            "acquisition_rate_hz",
            "estimation_rate_hz",
            "reference_encoder_counts_per_rev",
        )
        require_nonnegative(self, "current_noise_a", "force_sensor_noise_n", "current_filter_s")
