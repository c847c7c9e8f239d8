"""The held-out identification check (`participant_fit.validate`) and the hierarchical
estimator (`participant_fit.estimate`) on a synthetic design whose moments are known
functions of the traits: a trait that moves a moment is told, one that moves none is
not, and the EM recovers a group's mean of a told trait."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from study.analysis.participant_fit.emulator import MomentEmulator, design_box, design_settings
from study.analysis.participant_fit.estimate import GroupEstimator
from study.analysis.participant_fit.validate import held_out_errors
from study.protocol.participants import PROFILES, TRAITS

MEASURES = ("completion_time_s", "peak_proximal_force_n")
NOISE = 0.02
"""SD of a trial's log measure about its law."""


def _law(traits: np.ndarray) -> np.ndarray:
    """Log measures of people with `traits`: the time follows the preferred speed, the
    force the caution; nothing follows the other five traits."""
    speed, caution = (
        traits[:, TRAITS.index("preferred_speed_m_s")],
        traits[:, TRAITS.index("caution")],
    )
    return np.column_stack([np.log(0.25 / speed), np.log(0.4 + 0.5 * caution)])


def _trials(x: np.ndarray, repeats: int, rng: np.random.Generator) -> pd.DataFrame:
    rows = []
    for k, logs in enumerate(_law(x)):
        for r in range(repeats):
            for condition in ("VO", "HV"):
                noisy = np.exp(logs + rng.normal(0.0, NOISE, 2))
                rows.append({"setting": k, "condition": condition, "repeat": r,
                             **dict(zip(MEASURES, noisy, strict=True))})  # fmt: skip
    return pd.DataFrame(rows)


def test_held_out_people_tell_the_traits_their_moments_follow() -> None:
    x = design_settings(200, 1, design_box())
    errors = held_out_errors(x, _trials(x, 2, np.random.default_rng(1)), MEASURES, (), 2)
    spread = x.std(axis=0)
    told = [TRAITS.index("preferred_speed_m_s"), TRAITS.index("caution")]
    for j, trait in enumerate(TRAITS):
        if j in told:
            # the quadratic surface of log(0.25 / speed) and the 2 % noise: a few per cent
            # of the design's spread
            assert errors[j] < 0.15 * spread[j], trait
        else:
            # nothing follows it: the estimate stays at the wide prior's centre, and its
            # error is the design's own spread about it
            assert errors[j] == pytest.approx(spread[j], rel=0.2), trait


def test_the_em_recovers_a_groups_mean_of_a_told_trait() -> None:
    rng = np.random.default_rng(2)
    x = design_settings(200, 1, design_box())
    emulator = MomentEmulator().fit(x, _trials(x, 2, rng), MEASURES)
    # 12 people, their speeds from N(0.010, 0.002): far below the novices' prior 0.014
    speed = TRAITS.index("preferred_speed_m_s")
    people = np.tile([getattr(PROFILES["novice"], t)[0] for t in TRAITS], (12, 1))
    people[:, speed] = rng.normal(0.010, 0.002, 12)
    y = np.column_stack([_law(people)] * 2) + rng.normal(0.0, NOISE / np.sqrt(3), (12, 4))
    fit = GroupEstimator(emulator, PROFILES["novice"], [speed], 3.0).fit(y)
    assert fit.success
    # each person's own trials tell their speed: the group mean is the people's mean
    assert fit.mean[speed] == pytest.approx(people[:, speed].mean(), rel=0.03)
    np.testing.assert_allclose(fit.people[:, speed], people[:, speed], rtol=0.05)
    # a trait not fitted stays at its prior
    assert fit.mean[TRAITS.index("caution")] == PROFILES["novice"].caution[0]
