"""The LCCA trial's behavioural features (`study.tasks.lcca.features`), on a hand-built
trace whose every feature is known by construction, and their wiring into the task."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from study.protocol.tasks import get_task
from study.protocol.trial_run import simulate_trial
from study.tasks.lcca.features import AIM_FLOOR_RAD, FEATURES, lcca_features

OSTIUM_M = 0.25
DT = 0.01
TARGET = {"left common carotid"}
SPRING = 0.03
"""N m/rad: with the dial at 0.2 rad, -0.006 N m of the torque is the spring's."""


def _trace(stall_s: float = 0.6, rise_n_m: float = 0.003) -> pd.DataFrame:
    """Advance at 15 mm/s, slow to 8 mm/s 30 mm before the ostium, on into the target at
    12 mm/s; the first turn peaks at 0.8 s, swings back to 0.28 rad at 1.3 s and settles at
    0.3 rad; once in the target the
    tip sticks for `stall_s` s while the torque resisting the push grows by `rise_n_m`
    over the last second, then the hand backs off."""
    t = np.arange(0.0, 40.0, DT)
    x = np.empty_like(t)
    slow_at = OSTIUM_M - 0.030
    t_slow = slow_at / 0.015
    t_in = t_slow + 0.030 / 0.008
    for i, ti in enumerate(t):
        if ti < t_slow:
            x[i] = 0.015 * ti
        elif ti < t_in:
            x[i] = slow_at + 0.008 * (ti - t_slow)
        else:
            x[i] = OSTIUM_M + 0.012 * (ti - t_in)
    rot = np.interp(t, [0.0, 0.5, 0.8, 1.3, 1.7, 40.0], [0.0, 0.3, 0.35, 0.28, 0.3, 0.3])
    aim = np.full_like(t, 0.2)
    torque = np.full_like(t, -0.005)
    tip = x.copy()
    t_stick = t_in + 10.0
    t_back = t_stick + stall_s
    stuck = (t >= t_stick) & (t < t_back)
    tip[stuck] = tip[np.searchsorted(t, t_stick)]
    ramp = (t >= t_back - 1.0) & (t < t_back)
    torque[ramp] = -0.005 - rise_n_m * (t[ramp] - (t_back - 1.0))
    after = t >= t_back
    aim[after] = -0.2
    tip[after] = tip[np.searchsorted(t, t_back) - 1]
    x[after] = x[np.searchsorted(t, t_back) - 1]
    branch = np.where(x > OSTIUM_M, "left common carotid", "descending aorta")
    branch[(x > OSTIUM_M - 0.02) & (x <= OSTIUM_M)] = "aortic arch"
    return pd.DataFrame(
        {
            "t_s": t,
            "insertion_m": x,
            "rotation_rad": rot,
            "tip_x_m": tip,
            "tip_y_m": 0.0,
            "tip_z_m": 0.0,
            "branch": branch,
            "dial_angle_rad": aim,
            "dial_torque_n_m": torque,
        }
    )


def test_every_feature_of_a_hand_built_trace() -> None:
    f = lcca_features(_trace(), OSTIUM_M, 0.0, TARGET, SPRING)
    assert set(f) == set(FEATURES)
    assert f["advance_speed_m_s"] == pytest.approx(0.015, rel=1e-6)
    # the slowing is seen by a 0.1 s window centred on each sample: within a millimetre
    assert f["approach_m"] == pytest.approx(0.030, abs=0.001)
    assert f["approaches"] == 1
    assert f["target_speed_ratio"] == pytest.approx(0.012 / 0.015, rel=1e-6)
    assert f["aim_error_rad"] == pytest.approx(0.3 + AIM_FLOOR_RAD, abs=1e-9)
    assert f["turn_peak_s"] == pytest.approx(0.8, abs=DT)
    # it swings back to its next turning point at 1.3 s
    assert f["turn_swing_s"] == pytest.approx(0.5, abs=DT)
    # the stall: the tip stood still 0.6 s before the hand backed off, after covering its
    # last millimetre at 12 mm/s (plus one grid step)
    assert f["stall_s"] == pytest.approx(0.6 + 0.001 / 0.012 + DT, abs=2 * DT)
    assert f["stall_backoffs"] == 2
    # the torque beyond the spring rose 3 mN m over the second before backing off, felt
    # over the last 0.1 s (a mean 45 ms old), against its level 1-3 s before; plus 0.1 mN m
    assert f["peak_felt_rise_n_m"] == pytest.approx(0.003 * 0.945 + 1e-4, rel=0.01)


def test_the_features_follow_what_they_measure() -> None:
    base = lcca_features(_trace(), OSTIUM_M, 0.0, TARGET, SPRING)
    longer = lcca_features(_trace(stall_s=1.2), OSTIUM_M, 0.0, TARGET, SPRING)
    assert longer["stall_s"] - base["stall_s"] == pytest.approx(0.6, abs=2 * DT)
    # aiming at a branch 0.1 rad off reads as 0.1 rad less error
    off = lcca_features(_trace(), OSTIUM_M, 0.1, TARGET, SPRING)
    assert base["aim_error_rad"] - off["aim_error_rad"] == pytest.approx(0.1, abs=1e-9)


def test_a_trial_without_backing_off_or_target_has_those_features_undefined() -> None:
    frame = _trace()
    frame = frame[frame["insertion_m"] < OSTIUM_M - 0.01]
    f = lcca_features(frame, OSTIUM_M, 0.0, TARGET, SPRING)
    assert np.isnan(f["target_speed_ratio"])
    assert np.isnan(f["stall_s"])
    assert f["stall_backoffs"] == 1  # none, plus one
    # no rise of the felt resistance: the floor alone
    assert f["peak_felt_rise_n_m"] == pytest.approx(1e-4, abs=1e-12)
    assert f["advance_speed_m_s"] == pytest.approx(0.015, rel=1e-6)


def test_the_task_reads_its_features_off_a_simulated_trial() -> None:
    task = get_task("lcca")
    from study.protocol.traits import PROFILES, ParticipantTraits

    mean = {t: m for t, (m, _) in PROFILES["expert"].__dict__.items()}
    traits = ParticipantTraits(group="expert", **mean)
    context = task.session_context()
    result = simulate_trial(task, traits, "VO", 3, 60.0, context=context)
    f = task.trial_features(result.frame, context)
    # the advance speed is the participant's preferred speed (the dial's speed gain
    # times its aim, the hand's grip against the return spring taking a share)
    assert f["advance_speed_m_s"] == pytest.approx(mean["preferred_speed_m_s"], rel=0.15)
    # the samples table names the target by its abbreviation: the same features
    stored = result.frame.replace({"branch": {"left common carotid": "LCCA"}})
    assert task.trial_features(stored, context) == pytest.approx(f, nan_ok=True)
