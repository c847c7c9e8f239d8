"""Parameters of the NOTES haptic device's two decoupled axes ([notes], II-B, Fig. 8).

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

from dataclasses import dataclass, replace
from typing import ClassVar, Self

from teleop_core.errors import TeleopInputError
from teleop_core.validation import require_nonnegative, require_positive

DOFS = ("translation", "rotation")
CHIRP_BAND_HZ = (1.0, 30.0)
"""The paper's 1-30 Hz chirp (III-B): what `simulate.py` drives and `identify.py` fits."""
MSD_FIELDS = ("m_m", "m_s", "k_s", "b_m", "b_s")
"""Order of the linear parameters in every vector the fit and the transfer functions use."""
MSD_M_M, MSD_M_S, MSD_K_S, MSD_B_M, MSD_B_S = range(len(MSD_FIELDS))  # `as_tuple` indices


class NotesParamsError(TeleopInputError):
    """A NOTES device parameter out of its physical range."""


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
        require_positive(self, *MSD_FIELDS, error=NotesParamsError)

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        """(m_m, m_s, k_s, b_m, b_s), the order of MSD_FIELDS."""
        return (self.m_m, self.m_s, self.k_s, self.b_m, self.b_s)

    def scaled(self, factors: dict[str, float]) -> MsdParams:
        """A copy with each named parameter multiplied by its factor."""
        return replace(self, **{k: getattr(self, k) * v for k, v in factors.items()})


class _AxisParams:
    """What both axes share, read through the names of their own fields."""

    dof: ClassVar[str]
    _linear: ClassVar[tuple[str, str, str, str, str]]
    """The axis's fields for (m_m, m_s, k_s, b_m, b_s)."""
    _friction: ClassVar[tuple[str, str]]
    """The axis's (Coulomb, static) friction fields."""
    _limit: ClassVar[str]

    def _check(self) -> None:
        require_positive(self, *self._linear, self._limit, error=NotesParamsError)
        coulomb, static = self._friction
        require_nonnegative(self, coulomb, static, error=NotesParamsError)
        if getattr(self, static) < getattr(self, coulomb):
            raise NotesParamsError(f"{static} = {getattr(self, static)}; expected >= {coulomb}")

    @property
    def linear(self) -> MsdParams:
        """The Fig. 8 parameters in the axis's units."""
        return MsdParams(*(getattr(self, name) for name in self._linear))

    @property
    def coulomb(self) -> float:
        return float(getattr(self, self._friction[0]))

    @property
    def static(self) -> float:
        return float(getattr(self, self._friction[1]))

    @property
    def max_continuous(self) -> float:
        return float(getattr(self, self._limit))

    @property
    def gains(self) -> tuple[float, float]:
        """Transmission of a positive (CW) and of a negative (CCW) command."""
        return (1.0, 1.0)

    def with_linear(self, msd: MsdParams) -> Self:
        """A copy with the Fig. 8 parameters replaced."""
        return replace(self, **dict(zip(self._linear, msd.as_tuple(), strict=True)))  # type: ignore[type-var]

    def without_nonlinearities(self) -> Self:
        """The same linear device: no friction, the same transmission both ways."""
        return replace(self, **dict.fromkeys(self._friction, 0.0), **self._unit_gains())  # type: ignore[type-var]

    def _unit_gains(self) -> dict[str, float]:
        return {}


@dataclass(frozen=True)
class TranslationParams(_AxisParams):
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

    dof = "translation"
    _linear = (
        "manipulator_mass_kg",
        "scope_mass_kg",
        "spring_n_per_m",
        "manipulator_damping_n_s_per_m",
        "coupling_damping_n_s_per_m",
    )
    _friction = ("coulomb_friction_n", "static_friction_n")
    _limit = "max_continuous_force_n"

    def __post_init__(self) -> None:
        self._check()


@dataclass(frozen=True)
class RotationParams(_AxisParams):
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

    dof = "rotation"
    _linear = (
        "manipulator_inertia_kg_m2",
        "scope_inertia_kg_m2",
        "shaft_stiffness_n_m_per_rad",
        "manipulator_damping_n_m_s_per_rad",
        "shaft_damping_n_m_s_per_rad",
    )
    _friction = ("coulomb_friction_n_m", "static_friction_n_m")
    _limit = "max_continuous_torque_n_m"

    def __post_init__(self) -> None:
        self._check()
        require_positive(self, "ccw_transmission", "cw_transmission", error=NotesParamsError)

    @property
    def gains(self) -> tuple[float, float]:
        """Transmission of a positive (CW) and of a negative (CCW) command."""
        return (self.cw_transmission, self.ccw_transmission)

    def _unit_gains(self) -> dict[str, float]:
        return {"ccw_transmission": 1.0, "cw_transmission": 1.0}


AxisParams = TranslationParams | RotationParams


def default_params(dof: str) -> AxisParams:
    """The default parameters of one axis ("translation" or "rotation")."""
    if dof == "translation":
        return TranslationParams()
    if dof == "rotation":
        return RotationParams()
    raise NotesParamsError(f"dof {dof!r}; expected one of {', '.join(DOFS)}")
