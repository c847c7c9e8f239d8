"""The LCCA navigation phantom as a loop environment (called at the 1 kHz device rate).

A reduced guidewire model, cheap enough for a numba tick yet physical in its effects:

- The wire follows the vessel centreline: its tip sits `insertion - slack` along the
  current path. Paths fork at the branch ostia: when the tip crosses an ostium moving
  forward, it enters that branch if its angled tip, set by the rotation joystick, points
  within the branch's half-width of the ostium's azimuth; otherwise it stays in the
  aorta. Pulled back behind the ostium, it is in the aorta again.
- Sliding friction grows with the inserted length (introducer and vessel contact,
  `friction_n_per_m`, plus a viscous drag of the coated wire in saline) and with the
  wire's bending in curved vessel (normal force EI kappa^2 per unit length, times the
  friction coefficient), and the whole is
  amplified by the capstan effect over the turning angle up to the tip,
  T_proximal = T_distal e^(mu Theta) (Euler-Eytelwein belt friction). Friction is
  smoothed through zero speed over `smoothing_speed_m_s`.
- A tip that crosses an ostium pointing off the branch by between one and two
  half-widths catches the ostium's edge and is blocked there until pulled back.
- At a dead end (the valve, the end of a branch, a caught edge) the tip presses the
  wall with a stiff contact; past the wire's critical load (Euler buckling of the
  unsupported length in the wide aorta) further insertion goes into a prolapsing loop
  (`slack`) instead of the tip, and the loop's own wall contact adds friction; pulling
  back takes the loop out first.
- In curved vessel the tip bears on the outer wall with EI kappa / l_tip.

Outputs per tick: proximal force (what the drive feels), distal force (tip on the
wall), tip position, region code (`regions.REGIONS`) and success (tip `target_depth_m`
inside the LCCA).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from teleop_core._jit import njit
from teleop_core.errors import TeleopInputError
from teleop_core.loop.environments import Environment
from teleop_core.loop.layout import (
    E_BRANCH,
    E_DISTAL,
    E_PROXIMAL,
    E_SUCCESS,
    E_TIP_X,
    E_TIP_Y,
    E_TIP_Z,
)
from teleop_core.phantom.anatomy import (
    G_BEND,
    G_KAPPA,
    G_REGION,
    G_THETA,
    G_X,
    G_Y,
    G_Z,
    GEOMETRY_COLUMNS,
    STEP_M,
    ArchAnatomy,
    build_paths,
)
from teleop_core.phantom.regions import REGIONS
from teleop_core.validation import require_positive


@dataclass(frozen=True)
class GuidewireParams:
    """The guidewire in the phantom (a 0.035 in hydrophilic wire in a silicone model)."""

    bending_stiffness_n_m2: float = 1.0e-5
    """EI of a 0.035 in nitinol-core guidewire; assumption (published 0.5-2e-5 N m^2)."""
    friction_coefficient: float = 0.15
    """mu between the wire and the silicone wall (lubricated); assumption."""
    friction_n_per_m: float = 1.2
    """Sliding friction per metre inserted, straight (introducer, PTFE tube); assumption."""
    tip_length_m: float = 0.02
    """The angled tip's length, the lever of its wall contact; assumption."""
    wall_stiffness_n_per_m: float = 150.0
    """Contact stiffness of the blocked tip: the floppy distal segment bending plus the
    soft silicone wall (1.4 N after ~9 mm of push); assumption."""
    buckling_load_n: float = 1.4
    """Critical load for the wire to prolapse into a loop when the tip is blocked:
    pi^2 EI / (K l)^2 for l ~ 25 mm unsupported in the aorta, K ~ 1.7; assumption."""
    slack_friction_n_per_m: float = 6.0
    """Extra friction per metre of prolapsed loop pressing the aortic wall; assumption."""
    smoothing_speed_m_s: float = 0.001
    """Friction goes through zero over this speed (no stick-slip); assumption."""
    viscous_n_s_per_m2: float = 25.0
    """Drag per metre inserted per m/s: the hydrophilic coating sliding in the saline-
    filled phantom (at 0.25 m and 17 mm/s about a third of the sliding friction);
    assumption. Slower insertion, lower force."""
    tip_load_cv: float = 0.10
    """Trial-to-trial coefficient of variation of the angled tip's bearing load in a
    curve (EI kappa / l_tip): how the tip sits on the outer wall (its bend against the
    curve's plane, where along the floppy tip it touches) changes from one pass to the
    next; each trial draws a lognormal factor of mean 1. Assumption: contact-force
    catheters read 1-3 gf differently at different tip-to-wall angles at the same load
    (an in-vitro comparison of four catheter models, Authorea preprint 583547)."""
    distal_offset_sd_n: float = 0.003
    """SD of the distal force sensor's zero offset left after each trial's tare, about
    one resolution step of a Nano17-class six-axis sensor (1/320 N, ATI's data sheet);
    each trial draws its own; assumption."""

    def __post_init__(self) -> None:
        require_positive(
            self,
            "bending_stiffness_n_m2",
            "friction_coefficient",
            "friction_n_per_m",
            "tip_length_m",
            "wall_stiffness_n_per_m",
            "buckling_load_n",
            "slack_friction_n_per_m",
            "smoothing_speed_m_s",
            "viscous_n_s_per_m2",
        )
        if not (self.tip_load_cv >= 0 and self.distal_offset_sd_n >= 0):
            raise TeleopInputError(
                f"tip_load_cv {self.tip_load_cv!r}, distal_offset_sd_n "
                f"{self.distal_offset_sd_n!r}; expected values >= 0"
            )


# state
S_PATH, S_SLACK, S_PREV_INSERTION, S_PREV_TIP, S_CAUGHT = range(5)
STATE_SIZE = 5
CATCH_DEPTH_M = 0.002
"""How far past the ostium a tip that catches its edge gets before it is blocked."""
# header of the parameter vector
(
    H_NPATHS,
    H_NPTS,
    H_STEP,
    H_EI,
    H_MU,
    H_FLEN,
    H_LTIP,
    H_KWALL,
    H_FCR,
    H_FSLACK,
    H_VS,
    H_TARGET_PATH,
    H_TARGET_DEPTH,
    H_VISC,
    H_DISTAL_OFFSET,
) = range(15)
HEADER = 15
# per-path meta rows: end, ostium (arc length, m), ostium direction phi, half-width (rad)
PM_END, PM_OSTIUM, PM_PHI, PM_HALF = range(4)
PATH_META = 4


@njit(cache=True)
def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def lcca_phantom(state, params, insertion_m, speed_m_s, rotation_rad, dt_s, out):
    n_paths, n_pts, step = int(params[H_NPATHS]), int(params[H_NPTS]), params[H_STEP]
    meta = params[HEADER : HEADER + n_paths * PATH_META].reshape((n_paths, PATH_META))
    geo = params[HEADER + n_paths * PATH_META :].reshape((n_paths, n_pts, GEOMETRY_COLUMNS))
    path = int(state[S_PATH])
    # a prolapsed loop comes out first when the wire is pulled back
    d_ins = insertion_m - state[S_PREV_INSERTION]
    state[S_PREV_INSERTION] = insertion_m
    if d_ins < 0.0 and state[S_SLACK] > 0.0:
        state[S_SLACK] = max(state[S_SLACK] + d_ins, 0.0)
    tip = max(insertion_m - state[S_SLACK], 0.0)
    prev_tip = state[S_PREV_TIP]
    # branch choice at an ostium, by the angled tip's orientation: pointing within the
    # half-width it enters; within twice that it catches the ostium's edge
    caught = int(state[S_CAUGHT])
    if path == 0 and tip > prev_tip and caught == 0:
        for k in range(1, n_paths):
            ostium = meta[k, PM_OSTIUM]
            if prev_tip < ostium <= tip:
                off = abs(_wrap(rotation_rad - meta[k, PM_PHI]))
                if off <= meta[k, PM_HALF]:
                    path = k
                    break
                if off <= 2.0 * meta[k, PM_HALF]:
                    caught = k
                    break
    elif path != 0 and tip < meta[path, PM_OSTIUM]:
        path = 0
    if caught != 0 and tip < meta[caught, PM_OSTIUM]:
        caught = 0
    state[S_PATH] = path
    state[S_CAUGHT] = caught
    # dead end (or a caught ostium edge): wall contact, then prolapse beyond the
    # critical load
    end = meta[path, PM_END] if caught == 0 else meta[caught, PM_OSTIUM] + CATCH_DEPTH_M
    f_wall = 0.0
    if tip > end:
        f_wall = params[H_KWALL] * (tip - end)
        if f_wall > params[H_FCR]:
            state[S_SLACK] += (f_wall - params[H_FCR]) / params[H_KWALL]
            tip = insertion_m - state[S_SLACK]
            f_wall = params[H_FCR]
    state[S_PREV_TIP] = tip
    # geometry at the tip
    idx = min(int(min(tip, end) / step), n_pts - 1)
    g = geo[path, idx]
    theta = g[G_THETA]
    kappa_tip = g[G_KAPPA]
    # bending normal force along the inserted length: EI integral(kappa^2) ds
    bend = params[H_EI] * g[G_BEND]
    mu = params[H_MU]
    capstan = math.exp(mu * theta)
    f_curve_tip = params[H_EI] * kappa_tip / params[H_LTIP]
    sliding = (
        params[H_FLEN] * max(insertion_m, 0.0) + mu * bend + params[H_FSLACK] * state[S_SLACK]
    ) * math.tanh(speed_m_s / params[H_VS]) + params[H_VISC] * max(insertion_m, 0.0) * speed_m_s
    # T_proximal = T_distal e^(mu Theta) (capstan), friction spread along the path
    proximal = f_wall * capstan + sliding * math.sqrt(capstan)
    out[E_PROXIMAL] = proximal
    out[E_DISTAL] = f_wall + f_curve_tip + params[H_DISTAL_OFFSET]
    out[E_TIP_X] = g[G_X]
    out[E_TIP_Y] = g[G_Y]
    out[E_TIP_Z] = g[G_Z]
    out[E_BRANCH] = g[G_REGION]
    target = int(params[H_TARGET_PATH])
    out[E_SUCCESS] = (
        1.0 if (path == target and tip >= meta[target, PM_OSTIUM] + params[H_TARGET_DEPTH]) else 0.0
    )


@dataclass
class LccaPhantom:
    """The phantom with its guidewire; `environment()` plugs it into a `TeleopLoop`."""

    anatomy: ArchAnatomy = field(default_factory=ArchAnatomy)
    wire: GuidewireParams = field(default_factory=GuidewireParams)

    def __post_init__(self) -> None:
        self.geometry, self.meta = build_paths(self.anatomy)
        names = [b.name for b in self.anatomy.branches]
        if self.anatomy.target not in names:
            raise TeleopInputError(
                f"target branch {self.anatomy.target!r}; expected one of {names}"
            )
        self.target_path = names.index(self.anatomy.target) + 1

    def params(self) -> np.ndarray:
        w, (n_paths, n_pts, _) = self.wire, self.geometry.shape
        header = np.zeros(HEADER)
        header[H_NPATHS], header[H_NPTS], header[H_STEP] = n_paths, n_pts, STEP_M
        header[H_EI], header[H_MU] = w.bending_stiffness_n_m2, w.friction_coefficient
        header[H_FLEN], header[H_LTIP] = w.friction_n_per_m, w.tip_length_m
        header[H_KWALL], header[H_FCR] = w.wall_stiffness_n_per_m, w.buckling_load_n
        header[H_FSLACK], header[H_VS] = w.slack_friction_n_per_m, w.smoothing_speed_m_s
        header[H_TARGET_PATH] = self.target_path
        header[H_TARGET_DEPTH] = self.anatomy.target_depth_m
        header[H_VISC] = w.viscous_n_s_per_m2
        meta = np.array([[m["end"], m["ostium"], m["phi"], m["half"]] for m in self.meta])
        meta[0, PM_OSTIUM] = 1e9  # the aorta has no ostium
        return np.concatenate([header, meta.ravel(), self.geometry.ravel()])

    def trial_params(self, seed: int) -> np.ndarray:
        """`params()` with one trial's contact conditions, drawn from `seed`: the tip's
        bearing load times a lognormal factor of mean 1 (`tip_load_cv`, through the tip's
        lever) and the distal sensor's zero offset (`distal_offset_sd_n`)."""
        params, w = self.params(), self.wire
        rng = np.random.default_rng([seed, 0x71B])
        s = math.sqrt(math.log1p(w.tip_load_cv**2))
        params[H_LTIP] /= math.exp(rng.normal(-s * s / 2, s))
        params[H_DISTAL_OFFSET] = rng.normal(0.0, w.distal_offset_sd_n)
        return params

    def environment(self, seed: int | None = None) -> Environment:
        """The phantom for a loop; with a trial's `seed`, that trial's contact conditions
        (`trial_params`), else the nominal ones."""
        return Environment(
            lcca_phantom,
            self.params() if seed is None else self.trial_params(seed),
            np.zeros(STATE_SIZE),
            name="LCCA phantom",
            branches=REGIONS,
        )

    def ostium_m(self, branch: str) -> float:
        """Arc length from the access point to a branch's ostium."""
        names = [b.name for b in self.anatomy.branches]
        return float(self.meta[names.index(branch) + 1]["ostium"])

    def centreline(self, path: int) -> np.ndarray:
        """(n, 3) points of one path, for drawing."""
        n = round(self.meta[path]["end"] / STEP_M) + 1
        return self.geometry[path, :n, G_X : G_Z + 1]
