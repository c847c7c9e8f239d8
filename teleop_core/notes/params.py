"""Parameters of the NOTES haptic device's two decoupled axes (seed 001, II-B, Fig. 8).

Each axis is the paper's 4th-order mass-spring-damper of Fig. 8: the manipulator
(motor rotors and friction rollers, or motor and drive-shaft input) of mass M_m with a
damper b_m to ground, coupled through a spring k_s and a damper b_s to the scope (the
endoscope up to the hand) of mass M_s. On top of the linear model: Coulomb/static
friction on the manipulator (Karnopp), the actuator's continuous limit and, in
rotation, a direction-dependent transmission through the flexible shaft.

The paper's Table 1 (the fitted masses, springs and dampers) did not survive in the
seed, so the linear values here are assumptions chosen so that the clamped force
response F(s) gives the paper's force bandwidths (18.1 Hz translation, 5.7 Hz rotation)
and the translational settling time (0.12 s, IV). `MsdParams` is the generic
5-parameter view (kg or kg m^2, N/m or N m/rad, ...) that the transfer functions and
the grey-box fit use; the two axis classes carry the SI units in their field names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

from teleop_core.errors import TeleopInputError

DOFS = ("translation", "rotation")
MSD_FIELDS = ("m_m", "m_s", "k_s", "b_m", "b_s")
"""Order of the linear parameters in every vector the fit and the transfer functions use."""


class NotesParamsError(TeleopInputError):
    """A NOTES device parameter out of its physical range."""


def _require_positive(obj: object, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not (math.isfinite(value) and value > 0):
            raise NotesParamsError(f"{name} = {value!r}; expected a finite value > 0")


def _require_nonnegative(obj: object, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not (math.isfinite(value) and value >= 0):
            raise NotesParamsError(f"{name} = {value!r}; expected a finite value >= 0")


@dataclass(frozen=True)
class MsdParams:
    """The linear model of Fig. 8 in one axis's own units (translation: SI linear;
    rotation: the rotational counterparts, kg m^2, N m/rad, N m s/rad)."""

    m_m: float
    """Manipulator mass M_m (kg or kg m^2)."""
    m_s: float
    """Scope mass M_s (kg or kg m^2)."""
    k_s: float
    """Spring k_s between manipulator and scope (N/m or N m/rad)."""
    b_m: float
    """Manipulator damper to ground b_m (N s/m or N m s/rad)."""
    b_s: float
    """Damper b_s in parallel with k_s (N s/m or N m s/rad)."""

    def __post_init__(self) -> None:
        _require_positive(self, *MSD_FIELDS)

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        """(m_m, m_s, k_s, b_m, b_s), the order of MSD_FIELDS."""
        return (self.m_m, self.m_s, self.k_s, self.b_m, self.b_s)

    def scaled(self, factors: dict[str, float]) -> MsdParams:
        """A copy with each named parameter multiplied by its factor."""
        return replace(self, **{k: getattr(self, k) * v for k, v in factors.items()})


@dataclass(frozen=True)
class TranslationParams:
    """Translation: two omni-directional friction rollers on RE40 motors, spring-preloaded
    against the scope (II-B, Fig. 3)."""

    manipulator_mass_kg: float = 0.30
    """M_m: both RE40 rotors (2 x 142 g cm^2) and rollers reflected through a ~20 mm roller
    radius, plus the spring-loaded motor housings; assumption (Table 1 is missing)."""
    scope_mass_kg: float = 0.60
    """M_s: the endoscope's insertion tube and control head; assumption."""
    spring_n_per_m: float = 1970.0
    """k_s: rubber rollers and preload springs in series with the scope's axial compliance;
    assumption set with the dampers for the 18.1 Hz bandwidth and 0.12 s settling (IV)."""
    manipulator_damping_n_s_per_m: float = 15.0
    """b_m: motor and roller-bearing damping to ground; assumption (see spring_n_per_m)."""
    coupling_damping_n_s_per_m: float = 3.6
    """b_s: losses in the rubber rollers, parallel to k_s; assumption."""
    coulomb_friction_n: float = 0.35
    """Sliding friction on the manipulator, the source of the ramp hysteresis (Fig. 6);
    assumption."""
    static_friction_n: float = 0.35
    """Breakaway force of the manipulator (Karnopp's stick band); assumption: equal to the
    Coulomb level, as a larger breakaway gives stick-slip steps the paper's smooth ramps
    (Fig. 6) do not show."""
    max_continuous_force_n: float = 5.62
    """Maximum continuous force at the end effector (abstract, III-A). The motors saturate
    at this plus the Coulomb friction, so the loading branch of a ramp tops out here."""

    def __post_init__(self) -> None:
        _require_positive(self, *(f.name for f in fields(self) if "friction" not in f.name))
        _require_nonnegative(self, "coulomb_friction_n", "static_friction_n")
        if self.static_friction_n < self.coulomb_friction_n:
            raise NotesParamsError(
                f"static_friction_n = {self.static_friction_n}; expected >= coulomb_friction_n"
            )

    dof = "translation"

    @property
    def linear(self) -> MsdParams:
        """The Fig. 8 parameters (kg, N/m, N s/m)."""
        return MsdParams(
            self.manipulator_mass_kg,
            self.scope_mass_kg,
            self.spring_n_per_m,
            self.manipulator_damping_n_s_per_m,
            self.coupling_damping_n_s_per_m,
        )

    @property
    def coulomb(self) -> float:
        return self.coulomb_friction_n

    @property
    def static(self) -> float:
        return self.static_friction_n

    @property
    def max_continuous(self) -> float:
        return self.max_continuous_force_n

    @property
    def gains(self) -> tuple[float, float]:
        """Transmission of a positive and of a negative command (both 1 in translation)."""
        return (1.0, 1.0)

    def with_linear(self, msd: MsdParams) -> TranslationParams:
        """A copy with the Fig. 8 parameters replaced."""
        m_m, m_s, k_s, b_m, b_s = msd.as_tuple()
        return replace(
            self,
            manipulator_mass_kg=m_m,
            scope_mass_kg=m_s,
            spring_n_per_m=k_s,
            manipulator_damping_n_s_per_m=b_m,
            coupling_damping_n_s_per_m=b_s,
        )

    def without_nonlinearities(self) -> TranslationParams:
        """The same linear device with no friction (the linear model of Fig. 8 exactly)."""
        return replace(self, coulomb_friction_n=0.0, static_friction_n=0.0)


@dataclass(frozen=True)
class RotationParams:
    """Rotation: one RE40 motor turning the scope through a 20-inch flexible drive shaft
    (II-B, Fig. 4). Torques in N m, angles in rad."""

    manipulator_inertia_kg_m2: float = 7.7e-4
    """M_m: the RE40 rotor and the shaft's near end; assumption (Table 1 is missing)."""
    scope_inertia_kg_m2: float = 1.0e-3
    """M_s: the endoscope about its axis with the shaft's far end; assumption."""
    shaft_stiffness_n_m_per_rad: float = 0.68
    """k_s: torsional stiffness of the 20-inch (0.51 m) flexible shaft; assumption set with
    the dampers for the 5.7 Hz bandwidth (III-B)."""
    manipulator_damping_n_m_s_per_rad: float = 0.021
    """b_m: motor bearings and the shaft's casing drag; assumption."""
    shaft_damping_n_m_s_per_rad: float = 0.005
    """b_s: internal losses of the wound shaft, parallel to k_s; assumption."""
    coulomb_friction_n_m: float = 0.006
    """Sliding friction in the shaft's casing, the ramp hysteresis of Fig. 7; assumption."""
    static_friction_n_m: float = 0.006
    """Breakaway torque (Karnopp's stick band); assumption, equal to the Coulomb level as
    in translation."""
    ccw_transmission: float = 0.80
    """Fraction of a counter-clockwise (negative) command the shaft transmits: the winding
    of its wires loosens under CCW torque (III-A); assumption for the "significant loss"."""
    cw_transmission: float = 1.04
    """Fraction of a clockwise command transmitted: above 1 (the servo's torque constant 4 %
    above nominal; assumption) so that the 190 N mm command reaches the actuator's limit
    and the clamped ramp's CW peak is the paper's 190.05 N mm despite the friction."""
    max_continuous_torque_n_m: float = 0.19005
    """Maximum continuous torque at the end effector, 190.05 N mm (abstract, III-A)."""

    def __post_init__(self) -> None:
        _require_positive(self, *(f.name for f in fields(self) if "friction" not in f.name))
        _require_nonnegative(self, "coulomb_friction_n_m", "static_friction_n_m")
        if self.static_friction_n_m < self.coulomb_friction_n_m:
            raise NotesParamsError(
                f"static_friction_n_m = {self.static_friction_n_m}; "
                "expected >= coulomb_friction_n_m"
            )

    dof = "rotation"

    @property
    def linear(self) -> MsdParams:
        """The Fig. 8 parameters (kg m^2, N m/rad, N m s/rad)."""
        return MsdParams(
            self.manipulator_inertia_kg_m2,
            self.scope_inertia_kg_m2,
            self.shaft_stiffness_n_m_per_rad,
            self.manipulator_damping_n_m_s_per_rad,
            self.shaft_damping_n_m_s_per_rad,
        )

    @property
    def coulomb(self) -> float:
        return self.coulomb_friction_n_m

    @property
    def static(self) -> float:
        return self.static_friction_n_m

    @property
    def max_continuous(self) -> float:
        return self.max_continuous_torque_n_m

    @property
    def gains(self) -> tuple[float, float]:
        """Transmission of a positive (CW) and of a negative (CCW) command."""
        return (self.cw_transmission, self.ccw_transmission)

    def with_linear(self, msd: MsdParams) -> RotationParams:
        """A copy with the Fig. 8 parameters replaced."""
        m_m, m_s, k_s, b_m, b_s = msd.as_tuple()
        return replace(
            self,
            manipulator_inertia_kg_m2=m_m,
            scope_inertia_kg_m2=m_s,
            shaft_stiffness_n_m_per_rad=k_s,
            manipulator_damping_n_m_s_per_rad=b_m,
            shaft_damping_n_m_s_per_rad=b_s,
        )

    def without_nonlinearities(self) -> RotationParams:
        """The same linear device: no friction, the same transmission both ways."""
        return replace(
            self,
            coulomb_friction_n_m=0.0,
            static_friction_n_m=0.0,
            ccw_transmission=1.0,
            cw_transmission=1.0,
        )


AxisParams = TranslationParams | RotationParams


def default_params(dof: str) -> AxisParams:
    """The default parameters of one axis ("translation" or "rotation")."""
    if dof == "translation":
        return TranslationParams()
    if dof == "rotation":
        return RotationParams()
    raise NotesParamsError(f"dof {dof!r}; expected one of {', '.join(DOFS)}")
