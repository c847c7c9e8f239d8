"""Carry-overs that act on one measure alone: `force_carry_over` (the forces, not the
time) and `time_carry_over` (the time, not the forces).

Two kinds of test. On LCCA's own simulator, short paired simulations (the same people
and trial seeds with and without the effect) show that each family moves its measure
and leaves the other within a few per cent. On a closed-form task (the builder of
`closed_form_effects.py`), the loop on the people (`participant_fit.effects.search`)
names the family that acts on the measure the order effect is in, not a carry-over
that moves both, and adds nothing to a study without an effect.

The closed form follows what LCCA's simulator shows (elasticities measured there with
paired trials of 48 people, two per condition): the completion time goes as 1 / speed,
a little with the steering error (failed attempts) and the caution (a slower
approach); the peak forces grow with the speed (drag), the steering error (tips that
catch an ostium's edge) and, in VO, the time a stall must last before the person backs
off (in HV the felt threshold), and fall with the caution.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from study.analysis.participant_fit import effects
from study.analysis.participant_fit.emulator import MomentEmulator
from study.protocol.participant_effects import ParticipantEffect, TrialPlace, apply_effects
from study.protocol.tasks import get_task
from study.protocol.traits import TRAITS, ParticipantTraits, draw_traits
from study.protocol.trial_run import simulate_trial
from tests.study.closed_form_effects import closed_form_emulator, closed_form_study

MEASURES = ["completion_time_s", "peak_proximal_force_n", "peak_distal_force_n"]
NOISE = {"completion_time_s": 0.10, "peak_proximal_force_n": 0.15, "peak_distal_force_n": 0.20}
SIZES = {"outsider": 12, "novice": 8, "expert": 8}
K = 3
FREE = [TRAITS.index("preferred_speed_m_s"), TRAITS.index("steering_error_rad")]
"""The traits fitted per person: the speed and the aim (the aiming probe's trait), which
set most of a person's forces here; held at the group's mean, each person's forces
would pull their fitted speed and so their predicted time with them."""
SOFTER = ParticipantEffect(
    "force_carry_over", {"softer_vo_after_hv": 0.5, "softer_hv_after_vo": 0.0}
)
SLOWER = ParticipantEffect(
    "time_carry_over", {"slower_vo_after_hv": 0.2, "slower_hv_after_vo": 0.0}
)
VO_AFTER_HV = TrialPlace(position=3, block=1, condition="VO", first_condition="HV")


def test_the_forces_carry_over_aims_better_and_slows_a_little() -> None:
    # steering error times (1 - 0.5); speed times 0.5 ** 0.1 = 0.93303
    assert SOFTER.factors(VO_AFTER_HV) == pytest.approx(
        {"steering_error_rad": 0.5, "preferred_speed_m_s": 0.933033}
    )
    assert SOFTER.factors(TrialPlace(0, 0, "HV", "HV")) == {}
    assert SOFTER.factors(TrialPlace(3, 1, "HV", "VO")) == {
        "steering_error_rad": 1.0,
        "preferred_speed_m_s": 1.0,
    }


def test_the_time_carry_over_slows_and_backs_off_later() -> None:
    # speed times (1 - 0.2); the stall and the felt threshold times 0.8 ** -1.5 = 1.39754
    assert SLOWER.factors(VO_AFTER_HV) == pytest.approx(
        {"preferred_speed_m_s": 0.8, "visual_stall_s": 1.397542, "haptic_threshold_n_m": 1.397542}
    )


def _lcca_change(effect: ParticipantEffect, people: int = 16) -> dict[str, float]:
    """Geometric-mean change of each measure in VO after HV on LCCA's simulator: the
    same people (drawn per group) and trial seeds with and without `effect`."""
    rng = np.random.default_rng(7)
    logs = []
    for group in ("outsider", "novice", "expert"):
        for _ in range(people):
            person = draw_traits(group, rng)
            changed = apply_effects(person, (effect,), VO_AFTER_HV)
            for r in range(2):
                seed = 1000 * len(logs) + r
                a = simulate_trial(get_task("lcca"), person, "VO", seed, 180.0).summary
                b = simulate_trial(get_task("lcca"), changed, "VO", seed, 180.0).summary
                logs.append([math.log(b[m] / a[m]) for m in MEASURES])
    mean = np.mean(logs, axis=0)
    return {m: math.expm1(mean[k]) for k, m in enumerate(MEASURES)}


def test_on_lcca_the_forces_carry_over_moves_the_forces_not_the_time() -> None:
    change = _lcca_change(SOFTER)
    # 96 paired trials: the proximal force 11 % lower, the distal 22 %, the time 0.5 %
    assert change["peak_proximal_force_n"] < -0.07
    assert change["peak_distal_force_n"] < -0.15
    assert abs(change["completion_time_s"]) < 0.03


def test_on_lcca_the_time_carry_over_moves_the_time_not_the_forces() -> None:
    change = _lcca_change(SLOWER)
    # 96 paired trials: the time 24 % longer, the forces -2.4 % and +1.5 %
    assert change["completion_time_s"] > 0.15
    assert abs(change["peak_proximal_force_n"]) < 0.05
    assert abs(change["peak_distal_force_n"]) < 0.08


def measures(t: ParticipantTraits, condition: str, rng: np.random.Generator) -> dict[str, float]:
    relative = t.preferred_speed_m_s / 0.014
    steer = t.steering_error_rad / 0.32
    # in VO the stall a person waits for sets how far the tip is pushed into an obstacle,
    # in HV the felt threshold; HV's forces 40 % lower
    if condition == "VO":
        push = (t.visual_stall_s / 0.55) ** 0.22
    else:
        push = 0.6 * (t.haptic_threshold_n_m / 0.0037) ** 0.2
    mean = {
        "completion_time_s": 0.25
        / t.preferred_speed_m_s
        * steer**0.13
        * math.exp(0.46 * t.caution),
        "peak_proximal_force_n": 0.5
        * relative**0.42
        * steer**0.28
        * push
        * math.exp(-0.4 * t.caution),
        "peak_distal_force_n": 0.2
        * relative**0.45
        * steer**0.6
        * push**1.8
        * math.exp(-0.5 * t.caution),
    }
    return {m: mean[m] * math.exp(rng.normal(0.0, NOISE[m])) for m in MEASURES}


@pytest.fixture(scope="module")
def emulator() -> MomentEmulator:
    return closed_form_emulator(measures, MEASURES)


def _search(
    injected: tuple[ParticipantEffect, ...], emulator: MomentEmulator
) -> effects.EffectSearch:
    trials: pd.DataFrame = closed_form_study(measures, injected, SIZES, K)
    return effects.search(trials, emulator, FREE, [], seed=3, bootstrap=10)


def _flagged(found: effects.EffectSearch) -> set[tuple[str, str]]:
    return {(r["check"], r["measure"]) for r in found.before if r["flagged"]}


def test_an_order_effect_on_the_forces_alone_is_named_the_forces_carry_over(emulator) -> None:
    found = _search((SOFTER,), emulator)
    assert ("order", "peak_proximal_force_n") in _flagged(found)
    assert ("order", "completion_time_s") not in _flagged(found)
    # not the speed's carry-over nor the gentle one, which move the time too
    assert [e.family for e in found.effects] == ["force_carry_over"]
    share = found.effects[0].parameters
    assert 0.3 < share["softer_vo_after_hv"] < 0.7
    assert share["softer_hv_after_vo"] == 0.0
    assert found.verdict == "white"
    assert found.reduction() >= 0.25


def test_an_order_effect_on_the_time_alone_is_named_the_time_carry_over(emulator) -> None:
    found = _search((SLOWER,), emulator)
    assert ("order", "completion_time_s") in _flagged(found)
    assert ("order", "peak_proximal_force_n") not in _flagged(found)
    assert [e.family for e in found.effects] == ["time_carry_over"]
    share = found.effects[0].parameters
    # the share comes out 0.15 (the groups' speeds take part of the slowing)
    assert 0.1 < share["slower_vo_after_hv"] < 0.3
    assert share["slower_hv_after_vo"] == 0.0
    assert found.verdict == "white"
    assert found.reduction() >= 0.05


def test_a_study_without_an_effect_gets_none_of_them(emulator) -> None:
    found = _search((), emulator)
    assert found.effects == []
    assert found.verdict == "white"
