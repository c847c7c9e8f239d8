"""The loop on the people (`participant_fit.effects.search`) on a task whose measures
are closed forms of the traits, so that what the loop must find is known exactly and
the test runs in seconds (the engine-backed tests are
`test_participant_fit_effects.py`).

The closed-form task: a trial's completion time is 0.25 m / preferred speed (+ two
reaction times), its peak forces grow with the speed (and, in VO, with the time a stall
must last before it is taken for an obstacle), HV's forces 40 % lower; every measure
has its own lognormal trial noise. The studies are 20/8/8 people from the hand-set
profiles, 3 trials per condition, counterbalanced, as the issue's targets are stated.
A practice effect (the first trial 50 % slower, decaying over two trials) is mostly a
period effect in a two-period crossover: a carry-over free in both directions
reproduces that part exactly, and the loop once named it carry-over.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from study.analysis.participant_fit import effects
from study.analysis.participant_fit.emulator import MomentEmulator
from study.protocol.participant_effects import ParticipantEffect
from study.protocol.traits import TRAITS, ParticipantTraits
from tests.study.closed_form_effects import closed_form_emulator, closed_form_study

MEASURES = ["completion_time_s", "peak_proximal_force_n", "peak_distal_force_n"]
NOISE = {"completion_time_s": 0.10, "peak_proximal_force_n": 0.15, "peak_distal_force_n": 0.20}
SIZES = {"outsider": 20, "novice": 8, "expert": 8}
K = 3
FREE = [TRAITS.index("preferred_speed_m_s")]


def measures(t: ParticipantTraits, condition: str, rng: np.random.Generator) -> dict[str, float]:
    relative = t.preferred_speed_m_s / 0.014
    stall = (t.visual_stall_s / 0.55) ** 0.5 if condition == "VO" else 1.0
    hv = 0.6 if condition == "HV" else 1.0
    mean = {
        "completion_time_s": 0.25 / t.preferred_speed_m_s + 2 * t.reaction_s,
        "peak_proximal_force_n": 0.3 * relative**0.8 * stall * hv,
        "peak_distal_force_n": 0.1 * relative**0.5 * stall * hv,
    }
    return {m: mean[m] * math.exp(rng.normal(0.0, NOISE[m])) for m in MEASURES}


@pytest.fixture(scope="module")
def emulator() -> MomentEmulator:
    return closed_form_emulator(measures, MEASURES)


def study(injected: tuple[ParticipantEffect, ...], seed: int = 5) -> pd.DataFrame:
    return closed_form_study(measures, injected, SIZES, K, seed)


def _search(trials: pd.DataFrame, emulator: MomentEmulator) -> effects.EffectSearch:
    return effects.search(trials, emulator, FREE, [], seed=3, bootstrap=10)


def test_clean_closed_form_data_get_nothing(emulator) -> None:
    found = _search(study(()), emulator)
    assert found.effects == []
    assert found.verdict == "white"


def test_a_practice_effect_is_named_practice_not_carry_over(emulator) -> None:
    trials = study((ParticipantEffect("practice", {"slowing": 0.5, "decay_trials": 2.0}),))
    found = _search(trials, emulator)
    assert [e.family for e in found.effects][:1] == ["practice"]
    practice = found.effects[0].parameters
    # the parameters themselves, not a smaller slowing over fewer trials (the fit's
    # trait levels move with the effect: held where the fit without it put them, the
    # slowing came out 0.39 over 1.25 trials)
    assert 0.4 < practice["slowing"] < 0.6
    assert 1.5 < practice["decay_trials"] < 2.7
    # what remains is the cells' own noise: the held-out people's scatter, which no
    # model removes (the reduction is bounded by 1 - noise floor / error before)
    assert found.reduction() >= 0.20
    assert found.error_after.excess < 0.02 < found.error_before.excess
    # the model given the true effect instead of fitting it reaches the fitted one's
    # error (within the fit's own estimation error), and no model goes below the floor
    true = [ParticipantEffect("practice", {"slowing": 0.5, "decay_trials": 2.0})]
    known = effects.prediction_error(trials, emulator, [], FREE, [], 3, known=true)
    assert abs(known.error - found.error_after.error) < 0.1 * found.error_after.error
    # the RMS is over every (cell, measure): 3 groups x 6 positions x 2 orders, 3 measures
    # (a position and an order fix the condition), and each measure's RMS is its part
    out = found.to_dict()["prediction_error"]
    assert out["cells"] == 3 * 6 * 2 * 3
    mean_square = np.mean([v**2 for v in out["by_measure"]["after"].values()])
    assert out["after"] == pytest.approx(np.sqrt(mean_square))
    # the slowing acts on the completion time: its cells gain most
    by = out["by_measure"]
    assert by["after"]["completion_time_s"] < 0.7 * by["before"]["completion_time_s"]


def test_a_one_way_carry_over_is_named_with_the_other_direction_held_at_zero(emulator) -> None:
    trials = study((ParticipantEffect("carry_over", {"vo_after_hv": 0.3, "hv_after_vo": 0.0}),))
    found = _search(trials, emulator)
    assert [e.family for e in found.effects] == ["carry_over"]
    share = found.effects[0].parameters
    assert 0.2 < share["vo_after_hv"] < 0.4
    assert share["hv_after_vo"] == 0.0
    assert found.effects[0].intervals["hv_after_vo"] == (0.0, 0.0)
    assert found.reduction() >= 0.10
