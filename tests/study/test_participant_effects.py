"""Simulated people who vary from trial to trial and change over a session: the trial
state, the participant effects' multipliers, their place in a session, the TLX weights
per block, and bad effects in MODEL.json refused in one line."""

from __future__ import annotations

import json
import math
import zlib
from pathlib import Path

import numpy as np
import pytest

from study.errors import StudyInputError
from study.protocol.participant_effects import (
    ParticipantEffect,
    TrialPlace,
    apply_effects,
    effect_from_dict,
    session_place,
)
from study.protocol.traits import PROFILES, TRIAL_CV, draw_traits, trial_state
from tests.study.conftest import one_error_line


def _person():
    return draw_traits("novice", np.random.default_rng(5))


def test_a_trial_state_varies_about_the_person_with_the_stated_cv() -> None:
    person = _person()
    rng = np.random.default_rng(1)
    states = [trial_state(person, rng) for _ in range(4000)]
    for trait, cv in TRIAL_CV.items():
        values = np.array([getattr(s, trait) for s in states]) / getattr(person, trait)
        # a lognormal factor of mean 1 and CV cv (clipping into the bounds aside)
        assert values.mean() == pytest.approx(1.0, abs=0.02), trait
        assert values.std() == pytest.approx(cv, rel=0.08), trait
    # the traits not in TRIAL_CV are the person's in every trial
    assert {s.caution for s in states} == {person.caution}
    assert {s.steering_error_rad for s in states} == {person.steering_error_rad}


def test_three_trials_of_one_block_differ_to_the_stored_precision() -> None:
    """The measured trials of one block (their own seeds, as `study run` gives them) no
    longer repeat one another's completion time."""
    from study.protocol.default_estimator import load_estimator
    from study.protocol.tasks import get_task
    from study.protocol.trial_run import simulate_trial

    task = get_task("lcca")
    context, estimator = task.session_context(), load_estimator()
    person = draw_traits("expert", np.random.default_rng([1, zlib.crc32(b"P001")]))
    times = []
    for i in range(3):
        seed = zlib.crc32(f"1/P001/1/0/{i}/1".encode())
        s = simulate_trial(
            task, person, "HV", seed, 60.0, estimator=estimator, context=context
        ).summary
        times.append(round(s["completion_time_s"], 4))
    assert len(set(times)) == 3, times


def test_practice_slows_the_first_trials_and_decays() -> None:
    effect = ParticipantEffect("practice", {"slowing": 0.5, "decay_trials": 2.0})
    person = _person()
    speeds = [
        apply_effects(person, [effect], TrialPlace(p, p // 3, "VO", "VO")).preferred_speed_m_s
        for p in range(6)
    ]
    # speed / (1 + 0.5 exp(-p / 2)): 1/1.5 at the first trial
    for p, v in enumerate(speeds):
        assert v == pytest.approx(person.preferred_speed_m_s / (1 + 0.5 * math.exp(-p / 2)))
    assert speeds[0] == pytest.approx(person.preferred_speed_m_s / 1.5)


def test_carry_over_acts_only_in_a_second_block_after_the_other_condition() -> None:
    effect = ParticipantEffect("carry_over", {"vo_after_hv": 0.25, "hv_after_vo": -0.1})
    person = _person()
    vo_after_hv = apply_effects(person, [effect], TrialPlace(3, 1, "VO", "HV"))
    assert vo_after_hv.preferred_speed_m_s == pytest.approx(0.75 * person.preferred_speed_m_s)
    assert vo_after_hv.visual_stall_s == pytest.approx(0.75 * person.visual_stall_s)
    hv_after_vo = apply_effects(person, [effect], TrialPlace(3, 1, "HV", "VO"))
    assert hv_after_vo.preferred_speed_m_s == pytest.approx(1.1 * person.preferred_speed_m_s)
    for first_block in (TrialPlace(0, 0, "VO", "VO"), TrialPlace(1, 0, "HV", "HV")):
        assert apply_effects(person, [effect], first_block) == person
    # an effect of another group leaves the person as they are
    experts = ParticipantEffect(
        "carry_over", {"vo_after_hv": 0.25, "hv_after_vo": 0.0}, ("expert",)
    )
    assert apply_effects(person, [experts], TrialPlace(3, 1, "VO", "HV")) == person


def test_fatigue_and_effects_multiply_and_stay_in_bounds() -> None:
    fatigue = ParticipantEffect("fatigue", {"rate": 0.05})
    practice = ParticipantEffect("practice", {"slowing": 3.0, "decay_trials": 20.0})
    person = _person()
    place = TrialPlace(4, 1, "HV", "VO")
    both = apply_effects(person, [fatigue, practice], place)
    expected = person.preferred_speed_m_s * math.exp(-0.2) / (1 + 3.0 * math.exp(-4 / 20))
    assert both.preferred_speed_m_s == pytest.approx(max(expected, 0.005))
    assert both.reaction_s == pytest.approx(person.reaction_s * math.exp(0.2))


def test_a_session_place_counts_measured_trials_and_practice_back() -> None:
    # blocks VO then HV, 3 measured trials each, one practice trial before each
    assert session_place(["VO", "HV"], 0, 2, 3) == TrialPlace(2, 0, "VO", "VO")
    assert session_place(["VO", "HV"], 1, 0, 3) == TrialPlace(3, 1, "HV", "VO")
    assert session_place(["VO", "HV"], 1, 0, 3, practice=True, n_practice=1) == TrialPlace(
        2, 1, "HV", "VO"
    )


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"family": "boredom", "parameters": {}}, "family = 'boredom'; expected one of practice"),
        (
            {"family": "practice", "parameters": {"slowing": 0.5}},
            "practice: decay_trials = None; expected a number in [0.3, 20]",
        ),
        (
            {"family": "fatigue", "parameters": {"rate": {"value": 2.0}}},
            "fatigue: rate = 2.0; expected a number in [-0.1, 0.1]",
        ),
    ],
)
def test_a_bad_effect_is_refused(entry: dict, message: str) -> None:
    with pytest.raises(StudyInputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        effect_from_dict(entry, "participant_effects[0]")


def test_an_unexplained_person_is_never_simulated() -> None:
    assert effect_from_dict({"family": "unexplained_person", "participants": ["P003"]}, "x") is None


def test_a_model_with_a_bad_effect_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import dataclasses

    groups = {
        g: {t: {"mean": m, "sd": s} for t, (m, s) in dataclasses.asdict(p).items()}
        for g, p in PROFILES.items()
    }
    model = {
        "format": "haptic-study participant model",
        "task": "lcca",
        "data_source": "simulated",
        "groups": groups,
        "participant_effects": [
            {
                "family": "practice",
                "parameters": {"slowing": {"value": 9.0}, "decay_trials": {"value": 2.0}},
            }
        ],
    }
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model))
    out = tmp_path / "t.csv"
    line = one_error_line(
        capsys,
        [
            "simulate",
            "--group",
            "novice",
            "--condition",
            "VO",
            "--out",
            str(out),
            "--participants",
            str(path),
        ],
    )
    assert line.endswith(
        "participant_effects[0]: participant effect practice: slowing = 9.0; expected a "
        "number in [0, 3]"
    ), line
    assert not out.exists()


def test_a_model_with_an_effect_simulates_it() -> None:
    from study.protocol.participant_model import model_from_dict

    groups = {
        "novice": {t: {"mean": m, "sd": s} for t, (m, s) in PROFILES["novice"].__dict__.items()}
    }
    model = model_from_dict(
        {
            "format": "haptic-study participant model",
            "task": "lcca",
            "data_source": "simulated",
            "groups": groups,
            "participant_effects": [
                {
                    "family": "practice",
                    "groups": ["novice"],
                    "parameters": {
                        "slowing": {"value": 0.5, "ci95": [0.4, 0.6]},
                        "decay_trials": {"value": 2.0},
                    },
                },
                {"family": "unexplained_person", "participants": ["P002"]},
            ],
        },
        "m.json",
    )
    assert model.participant_effects == (
        ParticipantEffect("practice", {"slowing": 0.5, "decay_trials": 2.0}, ("novice",)),
    )


def test_tlx_weights_differ_between_a_persons_blocks() -> None:
    from study.protocol.simulated_tlx import (
        block_preference,
        pairwise_choices,
        person_preference,
    )

    differ = 0
    for person in range(20):
        rng = np.random.default_rng([3, person])
        preference = person_preference(rng)
        vo = pairwise_choices(3, f"P{person:03d}", rng, block_preference(preference, rng))
        hv = pairwise_choices(3, f"P{person:03d}", rng, block_preference(preference, rng))
        differ += vo != hv
    # 15 choices with a block's own shift of the weights: hardly anyone repeats all 15
    assert differ >= 18


def test_obstacles_felt_in_the_hand_relieve_the_tlx_of_watching_for_them() -> None:
    from study.protocol.simulated_tlx import block_ratings

    scales = ("mental", "physical", "temporal", "performance", "effort", "frustration")
    offsets = dict.fromkeys(scales, -20.0)  # away from the form's ends: nothing clipped

    def rate(seen: int, felt: int) -> dict[str, int]:
        # the same rating noise each time: only the obstacles differ
        return block_ratings([30.0], [0], [True], np.random.default_rng(7), offsets, seen, felt)

    # five obstacles all spotted on the screen (nothing to feel, as in VO) against the
    # same five all felt first: the seen stalls' own terms (mental 6, frustration 5
    # each) and watching for all of them (mental 30, frustration 15) against none;
    # the differences are multiples of the form's steps of 5, so rounding keeps them
    watched, felt = rate(5, 0), rate(0, 5)
    assert watched["mental"] - felt["mental"] == 5 * 6 + 30
    assert watched["frustration"] - felt["frustration"] == 5 * 5 + 15
    assert watched["physical"] == felt["physical"]
    # a block without obstacles was all watched, whatever the condition
    calm = rate(0, 0)
    assert calm["mental"] - felt["mental"] == 30
    assert calm["frustration"] - felt["frustration"] == 15
