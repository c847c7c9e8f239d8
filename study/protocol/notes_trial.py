"""One simulated NOTES trial: the abdomen, the 2-DOF device, a simulated participant.

The participant is the LCCA participant's person (the same `ParticipantTraits`: speed,
reaction, steering error, caution, comfort) doing the NOTES task through the same
driver interface (`teleop_core.loop.drivers`): it advances the scope to the posterior
fornix, pushes through it, then advances to the target depth while rolling the scope
to the target's angle, and ends the trial there. What it perceives is the screen
(depth, roll, region, after `reaction_s`) and, in HV, the resistance on its hand, which
shows as the scope lagging its aim (`dial_angle_rad`). It eases off in proportion to
its caution when the felt force passes its comfort level, and pushes harder when the
screen shows the scope stalled for `visual_stall_s` (in HV the device resists; in VO
nothing physical does, so only the virtual tissue's demand rises).

Summary (seed 001, IV): completion time, peak demanded and rendered force and torque,
and the fraction of the time the demanded push exceeds the device's continuous force
(the paper's surgeons: 23.57 %). The study database stores them under these names
(`study.protocol.tasks.notes`).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
import pandas as pd

from study.errors import StudyInputError
from study.protocol.lcca_trial import CONDITIONS
from study.protocol.participants import ParticipantTraits
from study.protocol.tasks import TrialResult
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
TRIAL_COLUMNS = {c: c for c in task.SAMPLE_COLUMNS} | {
    "proximal_force_n": "force_demanded_n",
    "proximal_force_est_n": "force_rendered_n",
    "distal_force_n": "tip_force_n",
    "dial_torque_n_m": "torque_rendered_n_m",
    "branch": "region",
}
"""Sample column -> NOTES TRIAL.csv column."""


class NotesParticipant(Driver):
    """A simulated participant with `traits` doing the NOTES task."""

    rate_hz = 25.0
    """Decisions at 25 Hz, as the LCCA participant (the endoscope video's frame rate)."""

    def __init__(self, traits: ParticipantTraits, give_up_s: float = 180.0) -> None:
        self.traits = traits
        self.give_up_s = give_up_s

    def start(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._seen: deque[OperatorView] = deque()
        self.push = 1.0
        self.roll_error = float(rng.normal(0.0, 0.3 * self.traits.steering_error_rad))
        self._stall_since = math.nan
        self._stall_depth = 0.0
        self._at_depth_since = math.nan
        self.stalls_seen = 0
        self.eased = 0

    def act(self, view: OperatorView) -> HandAction:
        tr = self.traits
        self._seen.append(view)
        while len(self._seen) > 1 and self._seen[1].t_s <= view.t_s - tr.reaction_s:
            self._seen.popleft()
        seen = self._seen[0]
        if view.success:
            return HandAction(done=True)
        if view.t_s >= self.give_up_s:
            return HandAction(done=True)
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
        speed = tr.preferred_speed_m_s * max(min(remaining / approach, 1.0), -1.0)
        # stalled on screen: push harder
        if (
            abs(remaining) > task.TARGET_TOLERANCE_M
            and abs(seen.insertion_m - self._stall_depth) < 0.002
        ):
            if math.isnan(self._stall_since):
                self._stall_since = view.t_s
            elif view.t_s - self._stall_since > tr.visual_stall_s:
                self.push = min(self.push * PUSH_GROWTH, 20.0)
                self.stalls_seen += 1
                self._stall_since = view.t_s
        else:
            self._stall_since = math.nan
            self._stall_depth = seen.insertion_m
        aim = speed * self.push
        # felt resistance (HV): the scope lagging the aim, the hand's own push
        felt = task.HAND_DAMPING_N_S_PER_M * abs(
            aim - view.dial_angle_rad * task.SPEED_GAIN_M_S_PER_RAD
        )
        if felt > COMFORT_FORCE_PER_TORQUE * tr.comfort_torque_n_m:
            aim *= 1.0 - 0.5 * tr.caution
            self.eased += 1
        # roll towards the target angle once through the fornix
        roll_rate = 0.0
        if seen.branch in ("cavity", "target"):
            err = task.TARGET_ROLL_RAD + self.roll_error - seen.rotation_rad
            roll_rate = float(np.clip(3.0 * err, -1.0, 1.0))
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


def trial_frame(samples: np.ndarray) -> pd.DataFrame:
    """NOTES TRIAL.csv's columns from the loop's samples."""
    frame = pd.DataFrame(samples, columns=list(task.SAMPLE_COLUMNS))
    frame["branch"] = np.asarray(task.REGIONS, dtype=object)[frame["branch"].astype(int)]
    return frame[list(TRIAL_COLUMNS)].rename(columns=TRIAL_COLUMNS)


def measures(frame: pd.DataFrame, success: bool) -> dict[str, Any]:
    """The NOTES summary of one trial from its TRIAL frame."""
    n = len(frame)
    limit = TranslationParams().max_continuous_force_n

    def peak(column: str) -> float:
        return float(frame[column].abs().max()) if n else 0.0

    return {
        "success": bool(success),
        "completion_time_s": float(frame["t_s"].iloc[-1]) if n else 0.0,
        "peak_force_demanded_n": peak("force_demanded_n"),
        "peak_force_rendered_n": peak("force_rendered_n"),
        "peak_torque_demanded_n_m": peak("torque_demanded_n_m"),
        "peak_torque_rendered_n_m": peak("torque_rendered_n_m"),
        "peak_tip_force_n": peak("tip_force_n"),
        "push_over_capacity_fraction": float(np.mean(frame["force_demanded_n"] > limit))
        if n
        else 0.0,
        "device_limits": {
            "force_n": limit,
            "torque_n_m": RotationParams().max_continuous_torque_n_m,
        },
    }


def run_notes_trial(
    traits: ParticipantTraits, condition: str, seed: int, max_s: float = 180.0
) -> TrialResult:
    """Run one headless NOTES trial to success or `max_s`."""
    loop = notes_loop(condition, seed)
    participant = NotesParticipant(traits, give_up_s=max_s)
    loop.start(participant)
    chunks = []
    while loop.t_s < max_s - 1e-9 and not loop.done:
        chunks.append(loop.advance(min(1.0, max_s - loop.t_s)))
    frame = trial_frame(np.concatenate(chunks))
    summary = {
        "task": "notes",
        "group": traits.group,
        "condition": condition,
        "seed": seed,
        **measures(frame, loop.success),
        "stalls_seen": participant.stalls_seen,
        "participant": traits.to_dict(),
    }
    return TrialResult(frame, summary)
