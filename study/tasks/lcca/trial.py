"""One simulated LCCA trial: phantom + loop + a simulated participant, and its summary.

The summary measures are those the study analyses ([endovascular], IV-D): completion time,
peak proximal force (the estimate the robot renders, as a sensorless drive measures it;
the simulated reference is kept beside it), peak distal force (the phantom's sensor),
success, and wall contacts (distal force rising through `CONTACT_THRESHOLD_N`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from study.errors import StudyInputError
from study.protocol.design import KNOWN_CONDITIONS
from teleop_core.estimation.estimator import ForceEstimator
from teleop_core.loop.core import LoopConfig, TeleopLoop
from teleop_core.loop.layout import SAMPLE_COLUMNS
from teleop_core.loop.link import LinkParams
from teleop_core.master.params import HapticParams
from teleop_core.phantom.lcca import LccaPhantom
from teleop_core.phantom.regions import REGIONS

CONDITIONS = KNOWN_CONDITIONS
CONTACT_THRESHOLD_N = 0.2
"""Distal force above which the tip is taken to press a wall (above the ~0.1 N the
angled tip exerts passing the LCCA's curve); assumption."""
TRIAL_COLUMNS = (
    "t_s",
    "insertion_m",
    "rotation_rad",
    "tip_x_m",
    "tip_y_m",
    "tip_z_m",
    "branch",
    "proximal_force_n",
    "reference_force_n",
    "distal_force_n",
    "dial_angle_rad",
    "dial_torque_n_m",
)
"""TRIAL.csv's columns, the loop's under their own names (the estimate the dial renders,
`proximal_force_n`, before the true force it estimates, `reference_force_n`)."""


def condition_haptics(condition: str, haptic_gain: float | None = None) -> HapticParams:
    """VO: haptic torque off (the dial still self-centres), its gain 0 (none rendered,
    as a session records it); HV: on, at `haptic_gain`. The gain was checked where it
    entered (the design file, `study simulate --haptic-gain`, `run_trial`'s
    `Task.haptic_gain`); `HapticParams` refuses a negative one of its own."""
    if condition not in CONDITIONS:
        raise StudyInputError(f"condition {condition!r}; expected one of {', '.join(CONDITIONS)}")
    gain = HapticParams().haptic_gain_n_m_per_n if haptic_gain is None else haptic_gain
    if condition == "VO":
        return HapticParams(haptics_on=False, haptic_gain_n_m_per_n=0.0)
    return HapticParams(haptics_on=True, haptic_gain_n_m_per_n=gain)


def wall_contacts(distal_n: np.ndarray, threshold_n: float = CONTACT_THRESHOLD_N) -> int:
    """How many times the distal force rises through the threshold."""
    above = np.asarray(distal_n) > threshold_n
    return int(np.count_nonzero(above[1:] & ~above[:-1]) + (1 if len(above) and above[0] else 0))


def lcca_loop(
    condition: str,
    seed: int,
    estimator: ForceEstimator | None,
    haptic_gain: float | None = None,
    phantom: LccaPhantom | None = None,
    link: LinkParams | None = None,
) -> TeleopLoop:
    """The closed loop of one LCCA trial under `condition` (not yet started); `link`
    (delay, jitter, loss) applies to both directions, default the paper's wired link."""
    phantom = phantom or LccaPhantom()
    link = link or LinkParams()
    config = LoopConfig(
        haptics=condition_haptics(condition, haptic_gain), to_follower=link, to_master=link
    )
    return TeleopLoop(config, phantom.environment(seed), estimator=estimator, seed=seed)


def measures(frame: pd.DataFrame, success: bool) -> dict[str, Any]:
    """The study's summary measures of one trial from its TRIAL_COLUMNS frame."""
    return {
        "success": bool(success),
        "completion_time_s": float(frame["t_s"].iloc[-1]) if len(frame) else 0.0,
        # the largest force resisting insertion (0 if the estimate never turned positive)
        "peak_proximal_force_n": max(float(frame["proximal_force_n"].max()), 0.0)
        if len(frame)
        else 0.0,
        "peak_proximal_reference_force_n": float(frame["reference_force_n"].max())
        if len(frame)
        else 0.0,
        "peak_distal_force_n": max(float(frame["distal_force_n"].max()), 0.0)
        if len(frame)
        else 0.0,
        "wall_contacts": wall_contacts(frame["distal_force_n"].to_numpy()),
    }


def trial_frame(samples: np.ndarray) -> pd.DataFrame:
    """TRIAL.csv straight from the loop's sample array (TRIAL_COLUMNS' order, the vessels
    named in full): no frame of every loop column is made first (a participant fit makes
    one per simulated trial)."""
    names = np.asarray(REGIONS, dtype=object)
    return pd.DataFrame(
        {
            name: names[samples[:, SAMPLE_COLUMNS.index(name)].astype(int)]
            if name == "branch"
            else samples[:, SAMPLE_COLUMNS.index(name)]
            for name in TRIAL_COLUMNS
        }
    )
