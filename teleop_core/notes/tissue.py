"""The virtual abdomen of the NOTES task: the force and torque the tissue demands of the
scope along the transvaginal path ([notes], IV; the task in `teleop_core.notes.task`).

Owns the tissue's physics and its state (the friction's stick, the fornix's tear, the
fold), nothing of the device or the hand, so it can be checked on its own against
closed forms. Depth d is the scope's insertion from the introitus (m), roll phi its
rotation (rad, positive clockwise); force F is positive resisting insertion (a push),
torque T positive resisting clockwise roll.

The path, in the order the scope meets it:

- the vaginal canal, 0 < d < d_f (`fornix_depth_m`): the wall grips the inserted length
  with Coulomb friction per metre (`wall_friction_n_per_m`) and a viscous part per
  metre (`wall_damping_n_s_per_m2`), the same in both directions;
- the posterior fornix at d_f: a membrane tented by the tip, Kelvin-Voigt
  (k_m delta + c_m delta'), torn when the tenting delta reaches `fornix_tear_m` (soft
  tissue fails at a strain, so a faster push tears it at a higher force); after the
  tear the colpotomy grips the scope (`incision_friction_n`);
- the peritoneal cavity, d > d_f: the scope's shaft beyond the colpotomy is unsupported
  and, pushed, bows against the viscera; the resistance grows with the length in the
  cavity (`cavity_resistance_n_per_m`) and acts on a push only (pulling straightens the
  shaft and unloads what lies ahead of it). This is why a push exceeds a pull;
- a fold at `fold_depth_m` (e.g. the broad ligament) blocks a tip rolled clockwise of
  `fold_clear_roll_rad`: a stiff contact (`fold_stiffness_n_per_m`); a tip that crosses
  the fold's depth at a clear roll has passed it.

Friction is Dahl's model (Dahl 1968; alpha = 1): with z in [-1, 1] the share of the
Coulomb level, dz/dx = (1 - z sgn(v)) / delta, so a reversal goes through zero over a
pre-sliding distance delta and a scope held still keeps the friction it was pushed
with, which relaxes as soft tissue does, dz/dt = -z / tau (`relaxation_s`). Each tick
applies the exact solution over dt at constant speed. Written here rather than taken
from a library: none of the kept ones has a friction state model, and the Karnopp model
of `karnopp.py` is a stick-slip switch for the device, not a pre-sliding state.

Roll: the wall's friction is isotropic, so its torque level is the scope's radius times
the axial Coulomb level; in the cavity the articulated tip, bent off the axis by
`tip_offset_m`, sweeps the viscera when the scope rolls (`tip_lateral_force_n` times
that offset). The torque reaches the hand through the scope's insertion tube, whose
helical steel band transmits counter-clockwise less well (`ccw_transmission`), the
loss [notes] (III-A) reports for its own wound drive shaft.

Where the numbers come from: the surgeons' benchmark of [notes] (IV, [20]) gives only
maxima and a share of time (pull 4.5 N, push 9.9 N, CW / CCW torque 76.7 / 85 N mm,
push above 5.62 N for 23.57 % of the procedure). Every coefficient below is an
assumption, chosen so that these figures follow from a plausible procedure
(`study.tasks.notes.trial`), and each says which figure it was tuned against. The
closed forms the tests check: a steady pull at speed v in the cavity is
-(W z_s + c_w d_f v) with W = f_w d_f + F_inc and z_s = (v / delta) / (v / delta +
1 / tau); a steady push adds C (d - d_f) z_s; the torque of a steady roll is
R z_s clockwise and -R z_s / eta counter-clockwise with R = r W + F_lat e.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import TYPE_CHECKING

from teleop_core.notes.params import NotesParamsError

if TYPE_CHECKING:
    import numpy as np

TRIAL_CV: dict[str, float] = {
    "wall_friction_n_per_m": 0.15,
    "incision_friction_n": 0.15,
    "fornix_stiffness_n_per_m": 0.15,
    "fornix_tear_m": 0.15,
    "cavity_resistance_n_per_m": 0.15,
    "tip_lateral_force_n": 0.15,
    "tip_offset_m": 0.15,
    "roll_damping_n_m_s_per_rad": 0.15,
}
"""The tissue's trial-to-trial coefficient of variation of each coefficient that sets a
peak force or torque (assumption: soft tissue's friction, stiffness and failure strain
vary by 10-30 % between sites and with hydration and previous passes, the scope meets
the tissue a little differently each time, and the articulated tip is bent a little
differently, which moves its lateral offset; 15 % each gives the within-block CV of the
peak push and torque that docs/explanation/assumptions.md states). `TissueParams.for_trial` draws a
trial's tissue as these coefficients times lognormal factors of mean 1."""


@dataclass(frozen=True)
class TissueParams:
    """The tissue along the transvaginal path; every value an assumption (see above)."""

    fornix_depth_m: float = 0.09
    """Depth d_f of the posterior fornix from the introitus (vaginal length ~9 cm)."""
    wall_friction_n_per_m: float = 42.0
    """Coulomb friction f_w of the canal wall per metre gripped; with the incision's
    grip the pull's level at full contact is W = 4.38 N, ~4.1 N of it reached in a
    steady pull at an expert's 17 mm/s (z_s = 0.94), plus the viscous ~0.3 N: the
    surgeons' mean max pull, 4.5 N."""
    incision_friction_n: float = 0.6
    """Grip F_inc of the colpotomy, stretched round the scope, after the tear."""
    wall_damping_n_s_per_m2: float = 200.0
    """Viscous friction c_w of the canal wall per metre gripped, per m/s."""
    presliding_m: float = 0.003
    """Dahl pre-sliding distance delta along the axis: the mucosa dragged along before
    it slips (a few mm). Its stiffness W / delta (~1500 N/m) stays below the device's
    roller coupling (k_s = 1970 N/m): at delta = 1 mm the rendered friction chatters."""
    relaxation_s: float = 3.0
    """Time constant tau over which friction held still relaxes (soft tissue relaxes
    over seconds); with the procedure it sets how long a push stays above 5.62 N."""
    fornix_stiffness_n_per_m: float = 550.0
    """Membrane stiffness k_m against the tip."""
    fornix_damping_n_s_per_m: float = 30.0
    """Membrane damping c_m."""
    fornix_tear_m: float = 0.01
    """Tenting at which the membrane tears: k_m x 10 mm = 5.5 N; with the canal's
    ~3.6 N and the viscous parts (~0.8 N at an expert's speed) the surgeons' mean max
    push, 9.9 N."""
    cavity_resistance_n_per_m: float = 23.0
    """Push resistance C per metre of scope in the cavity (the bowed shaft on the
    viscera): 2.5 N at the target depth, so a steady push passes 5.62 N some 5 cm past
    the fornix; with the procedure this sets the share of time above 5.62 N (tuned to
    the surgeons' 23.57 %)."""
    tip_lateral_force_n: float = 2.2
    """Resistance F_lat of the viscera to the tip swept sideways by a roll."""
    tip_offset_m: float = 0.024
    """Lateral offset e of the articulated tip (a bending section of ~4 cm bent some
    40 degrees); with F_lat and the wall the roll's level R = r W + F_lat e = 74.7 N mm,
    73.5 N mm of it reached at 1 rad/s (z_s = 0.984), plus the viscous 3 N mm: the
    surgeons' CW 76.7 N mm."""
    scope_radius_m: float = 0.005
    """Radius r of the insertion tube (an adult gastroscope or colonoscope, 10-13 mm)."""
    presliding_rad: float = 0.05
    """Dahl pre-sliding angle in roll (3 degrees of wind-up of tube and tissue)."""
    roll_damping_n_m_s_per_rad: float = 0.003
    """Viscous part c_r of the roll's resistance (tube and tissue), per rad/s: 3 N mm at
    an expert's 1 rad/s; it makes the torque depend on how fast a person rolls."""
    ccw_transmission: float = 0.9
    """Share eta of a counter-clockwise torque the insertion tube's helical band passes
    on (clockwise: 1): 76.5 / 0.9 = 85 N mm, the surgeons' CCW; the ratio of their CW
    and CCW means, 0.90, is all that sets it."""
    fold_depth_m: float = 0.14
    """Depth of the fold between the fornix and the target."""
    fold_clear_roll_rad: float = -0.2
    """The tip passes the fold only rolled counter-clockwise of this (about -11 deg)."""
    fold_stiffness_n_per_m: float = 300.0
    """Stiffness of the fold against the tip."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "fold_clear_roll_rad":
                ok = math.isfinite(value)
            elif f.name == "ccw_transmission":
                ok = 0 < value <= 1
            else:
                ok = math.isfinite(value) and value > 0
            if not ok:
                raise NotesParamsError(f"{f.name} = {value!r}; expected a finite value > 0")
        if self.fold_depth_m <= self.fornix_depth_m + self.fornix_tear_m:
            raise NotesParamsError(
                f"fold_depth_m = {self.fold_depth_m!r}; expected beyond the fornix's tear "
                f"({self.fornix_depth_m + self.fornix_tear_m:g} m)"
            )

    def for_trial(self, rng: np.random.Generator) -> TissueParams:
        """The tissue as one trial meets it: each coefficient of `TRIAL_CV` times a
        lognormal factor of mean 1 and that CV, drawn from `rng`."""
        varied = {}
        for name, cv in TRIAL_CV.items():
            # log factor ~ N(-s^2 / 2, s^2), s^2 = log(1 + cv^2): E[factor] = 1, CV = cv
            sd = math.sqrt(math.log1p(cv * cv))
            varied[name] = getattr(self, name) * math.exp(rng.normal(-sd * sd / 2, sd))
        return replace(self, **varied)

    def wall_level_n(self, depth_m: float, breached: bool) -> float:
        """Coulomb level W of the canal wall (and the incision once torn), N."""
        gripped = min(max(depth_m, 0.0), self.fornix_depth_m)
        return self.wall_friction_n_per_m * gripped + (
            self.incision_friction_n if breached else 0.0
        )

    def cavity_level_n(self, depth_m: float, breached: bool) -> float:
        """Push-only Coulomb level C (d - d_f) of the shaft in the cavity, N."""
        return (
            self.cavity_resistance_n_per_m * max(depth_m - self.fornix_depth_m, 0.0)
            if breached
            else 0.0
        )

    def torque_level_n_m(self, depth_m: float, breached: bool) -> float:
        """Coulomb level R = r W (+ F_lat e in the cavity) of the roll, clockwise, N m."""
        tip = self.tip_lateral_force_n * self.tip_offset_m if breached else 0.0
        return self.scope_radius_m * self.wall_level_n(depth_m, breached) + tip


@dataclass(frozen=True)
class TissueState:
    force_n: float
    """Demanded force on the scope, positive resisting insertion (push)."""
    tip_force_n: float
    """The part that acts on the tip: the fornix membrane or the fold, >= 0."""
    torque_n_m: float
    """Demanded torque at the hand, positive resisting clockwise roll."""


def dahl_step(z: float, rate: float, dt_s: float, presliding: float, relaxation_s: float) -> float:
    """Dahl's state (alpha = 1) after dt at the constant `rate` (m/s or rad/s), then
    relaxed: z -> sgn(v) + (z - sgn(v)) exp(-|v| dt / delta), times exp(-dt / tau)."""
    if rate != 0.0:
        s = math.copysign(1.0, rate)
        z = s + (z - s) * math.exp(-abs(rate) * dt_s / presliding)
    return z * math.exp(-dt_s / relaxation_s)


class NotesAbdomen:
    """The tissue's state along the path; `reset` before each trial, `step` each tick."""

    def __init__(self, params: TissueParams | None = None) -> None:
        self.params = params or TissueParams()
        self.reset()

    def reset(self) -> None:
        self.breached = False
        self.passed_fold = False
        self.z_axial = self.z_cavity = self.z_roll = 0.0

    def at_fold(self, depth_m: float, roll_rad: float) -> bool:
        """The tip against the fold: past its depth, not passed, rolled where it blocks."""
        p = self.params
        return (
            self.breached
            and not self.passed_fold
            and depth_m >= p.fold_depth_m
            and roll_rad > p.fold_clear_roll_rad
        )

    def step(
        self,
        depth_m: float,
        roll_rad: float,
        speed_m_s: float,
        roll_rate_rad_s: float,
        dt_s: float,
    ) -> TissueState:
        """Advance the tissue's state by `dt_s` with the scope at (depth, roll) moving at
        (speed, roll rate); the force and torque it demands."""
        p = self.params
        if depth_m < p.fold_depth_m:
            self.passed_fold = False
        elif self.breached and not self.passed_fold and roll_rad <= p.fold_clear_roll_rad:
            self.passed_fold = True
        self.z_axial = dahl_step(self.z_axial, speed_m_s, dt_s, p.presliding_m, p.relaxation_s)
        self.z_cavity = dahl_step(self.z_cavity, speed_m_s, dt_s, p.presliding_m, p.relaxation_s)
        self.z_roll = dahl_step(
            self.z_roll, roll_rate_rad_s, dt_s, p.presliding_rad, p.relaxation_s
        )
        gripped = min(max(depth_m, 0.0), p.fornix_depth_m)
        # F_wall = W z + c_w L v
        force = p.wall_level_n(depth_m, self.breached) * self.z_axial
        force += p.wall_damping_n_s_per_m2 * gripped * speed_m_s
        # the bowed shaft in the cavity resists a push only
        force += p.cavity_level_n(depth_m, self.breached) * max(self.z_cavity, 0.0)
        tip = 0.0
        tenting = depth_m - p.fornix_depth_m
        if not self.breached and tenting > 0:
            # Kelvin-Voigt membrane: k_m delta + c_m delta', torn at delta = fornix_tear_m
            tip = max(
                p.fornix_stiffness_n_per_m * tenting + p.fornix_damping_n_s_per_m * speed_m_s, 0.0
            )
            if tenting >= p.fornix_tear_m:
                self.breached = True
        elif self.at_fold(depth_m, roll_rad):
            tip = p.fold_stiffness_n_per_m * (depth_m - p.fold_depth_m)
            # T = R z + c_r omega
        torque = p.torque_level_n_m(depth_m, self.breached) * self.z_roll
        torque += p.roll_damping_n_m_s_per_rad * roll_rate_rad_s
        # the tube passes a counter-clockwise torque at eta
        if torque < 0:
            torque /= p.ccw_transmission
        return TissueState(force + tip, tip, torque)
