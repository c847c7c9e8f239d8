"""One simulated NOTES trial: the abdomen, the 2-DOF device, a simulated participant.

The participant is the LCCA participant's person (the same `ParticipantTraits`: speed,
reaction, steering error, caution, comfort) doing the NOTES procedure through the same
driver interface (`teleop_core.loop.drivers`): through the canal and the posterior
fornix, a roll towards the target, the fold that sends it back ("pull back and look"),
a counter-clockwise roll past the fold's edge, and on to the target's depth and roll
(`NotesParticipant`). What it perceives is the screen (depth, roll, region, after
`reaction_s`) and, in HV, the resistance on its hand, which shows as the scope lagging
its aim (`dial_angle_rad`). Past its comfort it settles for a slower pace, in
proportion to its caution; it keeps its pace by pushing harder when the screen shows
the scope falling behind (in HV the device resists; in VO nothing physical does).
All its numbers are assumptions; the tissue's (`teleop_core.notes.tissue`) are tuned
so that simulated experts in VO meet the surgeons' benchmark of [notes] (IV), which
`study bench notes` checks.

Summary ([notes], IV): completion time, peak demanded and rendered force and torque,
the largest push and pull and the largest clockwise and counter-clockwise torque
demanded, and the fraction of the time the demanded push exceeds the device's
continuous force (the paper's surgeons: 23.57 %). The study database stores them under these names
(`study.tasks.notes.task`).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
import pandas as pd

from study.errors import StudyInputError
from study.protocol.design import KNOWN_CONDITIONS as CONDITIONS
from study.protocol.traits import ParticipantTraits, trial_state
from teleop_core.loop.drivers import (
    GRIP_DAMPING_N_M_S_PER_RAD,
    GRIP_STIFFNESS_N_M_PER_RAD,
    Driver,
    HandAction,
    OperatorView,
)
from teleop_core.notes import task
from teleop_core.notes.params import RotationParams, TranslationParams

COMFORT_FORCE_PER_TORQUE = 400.0
"""Felt scope force per unit of the trait `comfort_torque_n_m` (the dial's torque on
the fingers, 0.008-0.01 N m, maps to 3-4 N pushed along a scope); assumption."""
PUSH_GROWTH = 1.5
"""How much harder it pushes after each stall it sees; assumption."""
BACK_OFF_M = 0.01
"""How far it pulls back from the fold, times (1 + caution); assumption (a centimetre
or two, the "pull back and look" of endoscopy)."""
FOLD_MARGIN_RAD = math.radians(15.0)
"""How far past the fold's edge it aims its roll; assumption."""
PASS_MARGIN_M = 0.01
"""How far past the fold the tip goes before it turns to the target; assumption."""
ROLL_GAIN = 0.8
"""Roll rate per rad of roll error, times 1 / reaction_s (as the LCCA participant);
assumption."""
ROLL_RATE_RAD_S = 1.0
ROLL_PACE_M_S = 0.017
"""Fastest roll: 1 rad/s for a participant whose preferred speed is an expert's mean
(`PROFILES`), in proportion for the others (one pace for both hands); assumption."""


class NotesParticipant(Driver):
    """A simulated participant with `traits` doing the NOTES procedure.

    Phases (`phase`), an assumed transvaginal peritoneoscopy:

    1. "insert": advance at the preferred speed through the canal and the fornix; once
       the screen shows the cavity, roll towards the target's roll while advancing.
    2. At the fold (the screen's red-out, region "fold"): the endoscopist's rule, pull
       back and re-orient. "back_off" withdraws `BACK_OFF_M` (longer for the
       cautious), "turn" rolls counter-clockwise past the fold's edge with a steering
       error that shrinks with each attempt, "pass" re-advances until the tip is
       `PASS_MARGIN_M` past the fold.
    3. "target": roll back to the target's roll while advancing to its depth, slowing
       over an approach zone; at depth but off the roll, look again and correct.

    When the felt force (HV) passes its comfort it settles for a pace slower in
    proportion to its caution. It keeps its pace: where the screen shows the scope
    covering less than half the aimed way over `visual_stall_s`, it pushes (or pulls)
    `PUSH_GROWTH` harder (against a felt resistance, the cautious less so), and eases
    back once it keeps up. It rolls in proportion to the roll error (gain `ROLL_GAIN`
    / reaction_s) up to `ROLL_RATE_RAD_S` scaled by its pace.
    """

    rate_hz = 25.0
    """Decisions at 25 Hz, as the LCCA participant (the endoscope video's frame rate)."""

    def __init__(self, traits: ParticipantTraits, give_up_s: float = 180.0) -> None:
        self.person = traits
        """The person's traits; `traits` is the person as they are in the current trial."""
        self.traits = traits
        self.give_up_s = give_up_s

    def start(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.traits = trial_state(self.person, rng)
        self._seen: deque[OperatorView] = deque()
        self.effort = 1.0
        """How much harder than its pace it pushes (or pulls)."""
        self.phase = "insert"
        self.attempt = 0
        self.roll_error = float(rng.normal(0.0, 0.3 * self.traits.steering_error_rad))
        self.clear_aim = task.FOLD_CLEAR_ROLL_RAD
        self.back_off_to = 0.0
        self._pace_sign = 0.0
        self._last_aim = 0.0
        self._uneasy = False
        self._pace_since = self._pace_from = self._pace_expected = 0.0
        self._at_depth_since = math.nan
        self.stalls_seen = 0
        self.eased = 0

    def _roll_rate(self, aim_rad: float, seen: OperatorView) -> float:
        # proportional, with a gain the reaction delay keeps from overshooting
        # a gain matched to the reaction delay keeps the correction from overshooting
        return ROLL_GAIN * (aim_rad - seen.rotation_rad) / self.traits.reaction_s

    def _plan(self, view: OperatorView, seen: OperatorView) -> tuple[float, float]:
        """(aimed speed, roll rate) of the current phase."""
        tr = self.traits
        v = tr.preferred_speed_m_s
        if self.phase in ("insert", "pass", "target") and seen.branch == "fold":
            # red-out: pull back, re-orient past the fold's edge, a little better each try
            self.phase = "back_off"
            self.back_off_to = seen.insertion_m - BACK_OFF_M * (1.0 + tr.caution)
            sd = tr.steering_error_rad * 0.7**self.attempt
            self.clear_aim = (
                task.FOLD_CLEAR_ROLL_RAD - FOLD_MARGIN_RAD + float(self.rng.normal(0, sd))
            )
            self.attempt += 1
        if self.phase == "back_off":
            if seen.insertion_m > self.back_off_to:
                return -v, 0.0
            self.phase = "turn"
        if self.phase == "turn":
            # turned once near its aim, or clearly past the fold's edge (in HV the
            # proportional roll may stall on the tissue's friction short of its aim)
            near = abs(self.clear_aim - seen.rotation_rad) <= 0.05
            if not near and seen.rotation_rad > task.FOLD_CLEAR_ROLL_RAD - FOLD_MARGIN_RAD / 2:
                return 0.0, self._roll_rate(self.clear_aim, seen)
            self.phase = "pass"
        if self.phase == "pass":
            if seen.insertion_m < task.FOLD_M + PASS_MARGIN_M:
                return v, self._roll_rate(self.clear_aim, seen)
            self.phase = "target"
        # at depth but off the target's roll: look again and correct the roll aim
        if abs(task.TARGET_M - seen.insertion_m) < task.TARGET_TOLERANCE_M:
            if math.isnan(self._at_depth_since):
                self._at_depth_since = view.t_s
            elif view.t_s - self._at_depth_since > tr.visual_stall_s:
                self.roll_error *= 0.5
                self._at_depth_since = view.t_s
        # depth: advance to the target, slowing over an approach zone
        approach = 0.02 * (1.0 + tr.caution)
        remaining = task.TARGET_M - seen.insertion_m
        speed = v * max(min(remaining / approach, 1.0), -1.0)
        roll = 0.0
        if seen.branch in ("cavity", "target"):
            roll = self._roll_rate(task.TARGET_ROLL_RAD + self.roll_error, seen)
        return speed, roll

    def _keep_pace(self, view: OperatorView, seen: OperatorView, speed: float) -> None:
        """Push harder when the screen shows the scope falling behind the aimed speed
        over `visual_stall_s` (less than half the way), ease back when it keeps up."""
        tr = self.traits
        if speed == 0 or math.copysign(1.0, speed) != self._pace_sign:
            self._pace_sign = math.copysign(1.0, speed) if speed != 0 else 0.0
            self._pace_since, self._pace_from = view.t_s, seen.insertion_m
            self._pace_expected = 0.0
            return
        self._pace_expected += abs(speed) / self.rate_hz
        if view.t_s - self._pace_since < tr.visual_stall_s:
            return
        progress = self._pace_sign * (seen.insertion_m - self._pace_from)
        if progress < 0.5 * self._pace_expected:
            # against a resistance it feels, the cautious add effort more slowly
            growth = PUSH_GROWTH if not self._uneasy else 1 + (PUSH_GROWTH - 1) * (1 - tr.caution)
            self.effort = min(self.effort * growth, 20.0)
            self.stalls_seen += 1
        elif progress > self._pace_expected:
            self.effort = max(self.effort / PUSH_GROWTH, 1.0)
        self._pace_since, self._pace_from, self._pace_expected = view.t_s, seen.insertion_m, 0.0

    def act(self, view: OperatorView) -> HandAction:
        tr = self.traits
        self._seen.append(view)
        while len(self._seen) > 1 and self._seen[1].t_s <= view.t_s - tr.reaction_s:
            self._seen.popleft()
        seen = self._seen[0]
        if view.success or view.t_s >= self.give_up_s:
            return HandAction(done=True)
        speed, roll_rate = self._plan(view, seen)
        # felt resistance (HV): what its hand pushed with last, the scope lagging that
        # aim; past its comfort it settles for a slower pace, in proportion to caution
        felt = task.HAND_DAMPING_N_S_PER_M * abs(
            self._last_aim - view.dial_angle_rad * task.SPEED_GAIN_M_S_PER_RAD
        )
        self._uneasy = felt > COMFORT_FORCE_PER_TORQUE * tr.comfort_torque_n_m
        if self._uneasy:
            speed *= 1.0 - 0.5 * tr.caution
            self.eased += 1
        # and keeps that pace: harder where the scope falls behind it
        self._keep_pace(view, seen, speed)
        aim = speed * self.effort
        self._last_aim = aim
        # the roll: proportional, up to its fastest
        top = ROLL_RATE_RAD_S * tr.preferred_speed_m_s / ROLL_PACE_M_S
        roll_rate = min(max(roll_rate, -top), top)
        return HandAction(
            dial_target_rad=aim / task.SPEED_GAIN_M_S_PER_RAD,
            grip_stiffness_n_m_per_rad=GRIP_STIFFNESS_N_M_PER_RAD,
            grip_damping_n_m_s_per_rad=GRIP_DAMPING_N_M_S_PER_RAD,
            rotation_rate_rad_s=roll_rate,
        )


def notes_loop(condition: str, seed: int) -> task.NotesLoop:
    """The closed loop of one NOTES trial under `condition` (VO: nothing rendered)."""
    if condition not in CONDITIONS:
        raise StudyInputError(f"condition {condition!r}; expected one of {', '.join(CONDITIONS)}")
    return task.NotesLoop(haptics=condition == "HV", seed=seed)


def measures(frame: pd.DataFrame, success: bool) -> dict[str, Any]:
    """The NOTES summary of one trial from its TRIAL frame."""
    n = len(frame)
    limit = TranslationParams().max_continuous_force_n

    def peak(column: str) -> float:
        return float(frame[column].abs().max()) if n else 0.0

    def largest(column: str, sign: float) -> float:
        """Largest value of `column` in the direction `sign`, as a magnitude (0: none)."""
        return max(float((sign * frame[column]).max()), 0.0) if n else 0.0

    return {
        "success": bool(success),
        "completion_time_s": float(frame["t_s"].iloc[-1]) if n else 0.0,
        "peak_force_demanded_n": peak("force_demanded_n"),
        "peak_force_rendered_n": peak("force_rendered_n"),
        "peak_torque_demanded_n_m": peak("torque_demanded_n_m"),
        "peak_torque_rendered_n_m": peak("torque_rendered_n_m"),
        "peak_tip_force_n": peak("tip_force_n"),
        "peak_push_n": largest("force_demanded_n", 1.0),
        "peak_pull_n": largest("force_demanded_n", -1.0),
        "peak_torque_cw_n_m": largest("torque_demanded_n_m", 1.0),
        "peak_torque_ccw_n_m": largest("torque_demanded_n_m", -1.0),
        "push_over_capacity_fraction": float(np.mean(frame["force_demanded_n"] > limit))
        if n
        else 0.0,
        "device_limits": {
            "force_n": limit,
            "torque_n_m": RotationParams().max_continuous_torque_n_m,
        },
    }
