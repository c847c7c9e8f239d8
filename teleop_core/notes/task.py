"""The NOTES trial: transvaginal access and navigation to a target ([notes], II-A, IV).

Owns the virtual abdomen and the closed loop of one trial on the 2-DOF device. The
hand holds the physical scope; its insertion depth d and roll phi (the device's
encoders) place the virtual scope, whose tissue model gives the force and torque the
simulator *demands*. The device renders the demand, clipped at its continuous limits
(5.62 N, 190.05 N mm), through the Fig. 8 dynamics of each axis with the Karnopp /
direction compensator assumed ideal (the linear model with unit transmission) and the
manipulator's damping b_m compensated from the motor encoder's speed, as the paper
plans for its impedance controller (IV); in VO it renders no tissue (the controller
still cancels the damping, so the scope moves against the device's inertia only).

The tissue (`teleop_core.notes.tissue`): canal wall friction, the posterior fornix
torn at a tenting, the colpotomy's grip, the bowed shaft's push-only resistance in the
cavity, a fold that only a tip rolled counter-clockwise passes, and the roll's torque
through the scope's tube; its coefficients are assumptions tuned against the surgeons'
benchmark of [notes] (IV). The target lies at `TARGET_M` and roll `TARGET_ROLL_RAD`;
the trial succeeds when the tip is within `TARGET_TOLERANCE_M` and
`TARGET_ROLL_TOLERANCE_RAD` of it.

The operator is any `teleop_core.loop.drivers.Driver`, read the NOTES way: the hand
aims the scope's insertion speed at `dial_target_rad` x `SPEED_GAIN_M_S_PER_RAD` (the
same rate mapping a keyboard's advance/retract keys give in LCCA) with a grip of
damping `HAND_DAMPING_N_S_PER_M` scaled by the grip stiffness's share of the default
grip, and turns it at `rotation_rate_rad_s`. The view's `dial_angle_rad` is the speed
the scope actually reaches over the same gain, so a rendered resistance shows, as in
LCCA, as the scope lagging the hand's aim. All tissue numbers beyond the benchmarks
are assumptions.
"""

from __future__ import annotations

import math

import numpy as np

from teleop_core.loop.drivers import GRIP_STIFFNESS_N_M_PER_RAD, Driver, HandAction, OperatorView
from teleop_core.notes.layout import SAMPLE_COLUMNS
from teleop_core.notes.params import RotationParams, TranslationParams
from teleop_core.notes.regions import REGIONS
from teleop_core.notes.tissue import NotesAbdomen as TissueAbdomen
from teleop_core.notes.tissue import TissueParams

PULL_BENCHMARK_N = 4.5
PUSH_BENCHMARK_N = 9.9
CW_BENCHMARK_N_M = 0.0767
CCW_BENCHMARK_N_M = 0.085
PUSH_OVER_LIMIT_BENCHMARK = 0.2357
"""Mean max pull / push force, CW / CCW torque of 10 surgeons on a porcine model, and the
share of the procedure's time their push exceeded the device's 5.62 N (IV, [20])."""
TISSUE = TissueParams()
TISSUE_STREAM = 1
"""The second word of the trial tissue's seed ([seed, TISSUE_STREAM]): a stream apart
from the driver's."""
FORNIX_M = TISSUE.fornix_depth_m
"""Depth of the posterior fornix from the introitus (`TissueParams.fornix_depth_m`)."""
FOLD_M = TISSUE.fold_depth_m
FOLD_CLEAR_ROLL_RAD = TISSUE.fold_clear_roll_rad
"""The fold between fornix and target, and the roll counter-clockwise of which the tip
passes it (`TissueParams`)."""
TARGET_M = 0.20
TARGET_ROLL_RAD = math.radians(60.0)
TARGET_TOLERANCE_M = 0.01
TARGET_ROLL_TOLERANCE_RAD = math.radians(10.0)
"""Target in the peritoneal cavity (depth, roll) and how close counts; assumptions."""
SPEED_GAIN_M_S_PER_RAD = 0.05
"""Aimed speed per rad of `dial_target_rad` (the LCCA dial's k_v; assumption)."""
HAND_DAMPING_N_S_PER_M = 150.0
HAND_DAMPING_N_M_S_PER_RAD = 0.15
"""How hard the hand drives the scope towards its aimed speeds; assumptions."""
HAND_MAX_FORCE_N = 25.0
HAND_MAX_TORQUE_N_M = 0.4
"""Strongest push and twist a hand applies to the scope; assumptions."""
DEVICE_RATE_HZ = 1000.0
SAMPLE_RATE_HZ = 100.0


class NotesAbdomen(TissueAbdomen):
    """The tissue plus where the tip is, as the screen shows it (`REGIONS`)."""

    def region(self, depth_m: float, roll_rad: float) -> str:
        if self.at_target(depth_m, roll_rad):
            return "target"
        if not self.breached:
            return "fornix" if depth_m >= FORNIX_M - 0.005 else "canal"
        return "fold" if self.at_fold(depth_m, roll_rad) else "cavity"

    @staticmethod
    def at_target(depth_m: float, roll_rad: float) -> bool:
        return (
            abs(depth_m - TARGET_M) < TARGET_TOLERANCE_M
            and abs(roll_rad - TARGET_ROLL_RAD) < TARGET_ROLL_TOLERANCE_RAD
        )


class _Axis:
    """One device axis holding the scope: Fig. 8 with the hand's force on the scope mass."""

    def __init__(self, params: TranslationParams | RotationParams) -> None:
        self.m_m, self.m_s, self.k_s, self.b_m, self.b_s = params.linear.as_tuple()
        self.limit = params.max_continuous
        self.x_m = self.v_m = self.x_s = self.v_s = 0.0

    def step(self, command: float, hand: float, tissue_free: float, dt: float) -> float:
        """Advance one tick; returns the force the device puts on the scope."""
        # impedance controller: the rendered force plus the manipulator's own damping
        # (measured speed from the motor encoder), within the continuous limit
        f_act = min(max(command + self.b_m * self.v_m, -self.limit), self.limit)
        # force of spring and damper on the scope
        f_c = self.k_s * (self.x_m - self.x_s) + self.b_s * (self.v_m - self.v_s)
        self.v_m += dt * (f_act - self.b_m * self.v_m - f_c) / self.m_m
        self.x_m += dt * self.v_m
        self.v_s += dt * (f_c + hand + tissue_free) / self.m_s
        self.x_s += dt * self.v_s
        return f_c


class NotesLoop:
    """One NOTES trial's closed loop: `start(driver)`, then `advance(seconds)`.

    `haptics` False is VO (nothing rendered), True is HV. Samples come at 100 Hz with
    the columns of `SAMPLE_COLUMNS` (branch as an index into REGIONS).
    """

    def __init__(self, haptics: bool, seed: int = 0, tissue: TissueParams | None = None) -> None:
        self.haptics = haptics
        self.rng = np.random.default_rng(seed)
        # the trial's tissue from a stream of its own, so the driver's draws stay as
        # they were; `tissue` given: exactly that tissue (the closed-form checks)
        if tissue is None:
            tissue = TISSUE.for_trial(np.random.default_rng([seed, TISSUE_STREAM]))
        self.abdomen = NotesAbdomen(tissue)
        self.trans = _Axis(TranslationParams())
        self.rot = _Axis(RotationParams())
        self.t_s = 0.0
        self.done = False
        self.success = False
        self.driver: Driver | None = None
        self._action = HandAction()
        self._tick = 0

    def start(self, driver: Driver) -> None:
        self.driver = driver
        driver.start(self.rng)
        self._drv_every = round(DEVICE_RATE_HZ / (driver.rate_hz or SAMPLE_RATE_HZ))

    def _view(self) -> OperatorView:
        depth, roll = self.trans.x_s, self.rot.x_s
        return OperatorView(
            t_s=self.t_s,
            dial_angle_rad=self.trans.v_s / SPEED_GAIN_M_S_PER_RAD,
            dial_speed_rad_s=self.rot.v_s,
            insertion_m=depth,
            rotation_rad=roll,
            tip_m=(depth, 0.0, 0.0),
            branch=self.abdomen.region(depth, roll),
            success=self.success,
        )

    def advance(self, seconds: float) -> np.ndarray:
        """Run for `seconds` (or until done); return the samples taken, shape (n, 13)."""
        if self.driver is None:
            raise RuntimeError("start(driver) first")
        dt = 1.0 / DEVICE_RATE_HZ
        every = round(DEVICE_RATE_HZ / SAMPLE_RATE_HZ)
        rows = []
        end = self.t_s + seconds - 1e-9
        grip_share = 1.0
        while self.t_s < end and not self.done:
            if self._tick % self._drv_every == 0:
                self._action = self.driver.act(self._view())
                if self._action.done:
                    self.done = True
                    break
            a = self._action
            grip_share = a.grip_stiffness_n_m_per_rad / GRIP_STIFFNESS_N_M_PER_RAD
            tr, ro = self.trans, self.rot
            tissue = self.abdomen.step(tr.x_s, ro.x_s, tr.v_s, ro.v_s, dt)
            # the hand drives the scope towards the aimed speeds, within its strength
            aim = a.dial_target_rad * SPEED_GAIN_M_S_PER_RAD
            hand_f = HAND_DAMPING_N_S_PER_M * grip_share * (aim - tr.v_s)
            hand_f = min(max(hand_f, -HAND_MAX_FORCE_N), HAND_MAX_FORCE_N)
            hand_t = HAND_DAMPING_N_M_S_PER_RAD * (a.rotation_rate_rad_s - ro.v_s)
            hand_t = min(max(hand_t, -HAND_MAX_TORQUE_N_M), HAND_MAX_TORQUE_N_M)
            cmd_f = -tissue.force_n if self.haptics else 0.0
            cmd_t = -tissue.torque_n_m if self.haptics else 0.0
            # the virtual tissue acts on the virtual scope only: the physical scope feels
            # the device (rendered) and the hand
            rendered_f = tr.step(cmd_f, hand_f, 0.0, dt)
            rendered_t = ro.step(cmd_t, hand_t, 0.0, dt)
            self._tick += 1
            self.t_s = self._tick * dt
            if self.abdomen.at_target(tr.x_s, ro.x_s):
                self.success = True
            if self._tick % every == 0:
                rows.append(
                    (
                        self.t_s,
                        tr.x_s,
                        ro.x_s,
                        tr.x_s,
                        0.0,
                        0.0,
                        REGIONS.index(self.abdomen.region(tr.x_s, ro.x_s)),
                        tissue.force_n,
                        -rendered_f,
                        tissue.tip_force_n,
                        tr.v_s / SPEED_GAIN_M_S_PER_RAD,
                        -rendered_t,
                        tissue.torque_n_m,
                    )
                )
        return np.array(rows, dtype=float).reshape(-1, len(SAMPLE_COLUMNS))
