"""The loop on the people (`participant_fit.effects.search`) on LCCA studies whose
carry-over acts on one measure alone: the families whose shape the flagged structure
tests show are tried first, so a condition-order effect on the time alone is named
`time_carry_over` (not the carry-over that moves the forces too, which fits such trials
about as well, nor practice or fatigue), one on the forces alone `force_carry_over`,
and a study without an effect gets nothing.

The studies go through the real engine (LCCA's simulated participant carrying the
planted effect at each trial's place), kept small: 8 people per group, 3 trials per
condition; the emulator is built from 320 trait settings with one trial per condition
each and trials up to 180 s (a time-only share of 0.35 makes the VO trials after HV
about 40 % longer, which a 60 s cap would cut).
"""

from __future__ import annotations

import dataclasses

import pandas as pd
import pytest

from study.analysis.participant_fit import effects
from study.analysis.participant_fit.emulator import MomentEmulator
from study.analysis.participant_fit.fit import (
    FitSettings,
    build_emulator,
    plan_traits,
    read_data,
    simulate_people,
)
from study.protocol.participant_effects import FAMILIES, ParticipantEffect
from study.protocol.traits import PROFILES

SETTINGS = FitSettings(design=320, repeats=1, check=4, bootstrap=10, jobs=2, seed=3, max_s=180.0)
pytestmark = pytest.mark.timeout(1200)
TIME = "completion_time_s"
FORCES = ("peak_proximal_force_n", "peak_distal_force_n")
SLOWER = ParticipantEffect(
    "time_carry_over", {"slower_vo_after_hv": 0.35, "slower_hv_after_vo": 0.0}
)
"""VO after HV first 35 % slower, backing off a stalled tip later: the time longer, the
peak forces kept."""
SOFTER = ParticipantEffect(
    "force_carry_over", {"softer_vo_after_hv": 0.6, "softer_hv_after_vo": 0.0}
)
"""VO after HV first aimed with 60 % less steering error: the peak forces lower, the
time kept."""


@pytest.fixture(scope="module")
def emulator() -> MomentEmulator:
    return build_emulator("lcca", SETTINGS)


def _search(
    injected: tuple[ParticipantEffect, ...], seed: int, emulator: MomentEmulator
) -> effects.EffectSearch:
    truth = {g: [p] for g, p in PROFILES.items()}
    data_settings = dataclasses.replace(SETTINGS, seed=seed)
    trials: pd.DataFrame = simulate_people(
        "lcca", truth, 8, 3, data_settings, lambda *_: None, injected
    )
    data = read_data(trials, "lcca", emulator, "test data")
    plan = plan_traits(emulator, data, SETTINGS)
    return effects.search(data.trials, emulator, plan.free, plan.weak, SETTINGS.seed, bootstrap=20)


def _flagged(rows: list[dict]) -> set[tuple[str, str]]:
    return {(r["check"], r["measure"]) for r in rows if r["flagged"]}


def test_the_measures_kind_is_its_unit() -> None:
    assert effects.measure_kind(TIME) == "time"
    assert {effects.measure_kind(m) for m in FORCES} == {"force"}
    # a count (LCCA's approaches) is neither
    assert effects.measure_kind("approaches") is None


def _row(check: str, measure: str, flagged: bool = True) -> dict:
    return {"check": check, "measure": measure, "flagged": flagged}


def _turns(rows: list[dict], added: tuple[str, ...] = ()) -> list[tuple[list[str], str | None]]:
    return [(list(t.families), t.preferred) for t in effects.shaped_candidates(rows, added)]


def test_the_families_are_tried_in_the_shape_the_flagged_tests_show() -> None:
    on_time = [_row("order", TIME), _row("order", FORCES[0], False), _row("trend", TIME, False)]
    # the time-only carry-over first, practice and fatigue beside it (a period effect is
    # an order effect on the time too), then the carry-over that moves the forces as well
    assert _turns(on_time) == [
        (["time_carry_over", "practice", "fatigue"], "time_carry_over"),
        (["carry_over"], "carry_over"),
        (["gentle_carry_over", "force_carry_over"], None),
    ]
    on_forces = [_row("order", FORCES[0]), _row("order", FORCES[1])]
    assert _turns(on_forces) == [
        (["force_carry_over", "gentle_carry_over"], "force_carry_over"),
        (["carry_over"], "carry_over"),
        (["practice", "fatigue", "time_carry_over"], None),
    ]
    # a flagged trend: practice and fatigue compete with the shaped family on equal terms
    trend = [*on_forces, _row("trend", TIME)]
    assert _turns(trend)[0] == (
        ["force_carry_over", "gentle_carry_over", "practice", "fatigue"],
        None,
    )
    # on both kinds of measure, or a trend alone: every family in one turn, as equals
    both = [_row("order", TIME), _row("order", FORCES[1])]
    assert _turns(both) == [(list(FAMILIES), None)]
    assert _turns([_row("trend", TIME)]) == [(list(FAMILIES), None)]
    # what is added is not tried again
    assert _turns(on_time, ("time_carry_over",))[:2] == [
        (["practice", "fatigue"], None),
        (["carry_over"], "carry_over"),
    ]


def test_another_family_displaces_the_shaped_one_only_by_the_likelihood_ratio_margin() -> None:
    # chi-square quantiles at 1 - 0.01: 6.635 (fatigue, one parameter), 9.210 (practice)
    assert effects._candidate(
        [(500.0, "time_carry_over"), (494.0, "fatigue")], "time_carry_over"
    ) == (
        500.0,
        "time_carry_over",
    )
    assert effects._candidate(
        [(500.0, "time_carry_over"), (493.0, "fatigue")], "time_carry_over"
    ) == (
        493.0,
        "fatigue",
    )
    assert (
        effects._candidate([(500.0, "time_carry_over"), (491.0, "practice")], "time_carry_over")[1]
        == "time_carry_over"
    )
    assert effects._candidate([(500.0, "time_carry_over"), (494.0, "fatigue")], None) == (
        494.0,
        "fatigue",
    )


@pytest.mark.parametrize("seed", [7, 11, 13])
def test_an_order_effect_on_the_time_alone_is_named_the_time_carry_over(emulator, seed) -> None:
    found = _search((SLOWER,), seed, emulator)
    flagged = _flagged(found.before)
    assert ("order", TIME) in flagged
    assert not flagged & {("order", m) for m in FORCES}
    # not practice or fatigue, nor the carry-over that moves the forces too, which is
    # tried only after the time-only one fails
    assert [e.family for e in found.effects] == ["time_carry_over"]
    assert "carry_over" not in found.tried[0]["in_sample"]
    share = found.effects[0].parameters
    assert 0.2 < share["slower_vo_after_hv"] < 0.45
    assert share["slower_hv_after_vo"] == 0.0
    assert found.error_after.error < found.error_before.error
    assert found.verdict == "white"


def test_an_order_effect_on_the_forces_alone_is_named_the_forces_carry_over(emulator) -> None:
    found = _search((SOFTER,), 7, emulator)
    flagged = _flagged(found.before)
    assert flagged & {("order", m) for m in FORCES}
    assert ("order", TIME) not in flagged
    assert [e.family for e in found.effects] == ["force_carry_over"]
    # tried first, beside the gentle one, not the carry-over that moves the time too
    assert list(found.tried[0]["in_sample"]) == ["force_carry_over", "gentle_carry_over"]
    share = found.effects[0].parameters
    assert 0.35 < share["softer_vo_after_hv"] <= 0.6
    assert share["softer_hv_after_vo"] == 0.0
    assert found.reduction() >= 0.10


@pytest.mark.parametrize("seed", [7, 11])
def test_a_study_without_an_effect_gets_none_of_them(emulator, seed) -> None:
    found = _search((), seed, emulator)
    assert found.effects == []
    assert found.verdict == "white"
