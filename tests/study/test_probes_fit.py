"""The participant fit with probes: a trait a probe measures is fitted from the probe
trials with the task's data, so none is held at its prior; a participant missing a probe
still fits and the output says so.

The study is small (6 people per group, 2 LCCA trials per condition, capped at 60 s; an
emulator of 200 settings, as `test_participant_fit.py`), simulated through the real
engine; the probes are answered by the same simulated people (lapses and response
noise included). The haptic thresholds' and comfort torques' true group means are set
apart from the hand-set profiles, so recovering them tests the probes, not the priors.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from study.analysis.participant_fit.estimate import IDENTIFIED_RATIO
from study.analysis.participant_fit.fit import (
    FitSettings,
    build_emulator,
    fit_trials,
    simulate_people,
)
from study.probes import probe_names
from study.probes.measure import probe_table
from study.probes.runner import SimulatedResponder, run_probe
from study.protocol.traits import PROFILES, TRAITS, draw_traits

SETTINGS = FitSettings(design=200, repeats=1, check=4, bootstrap=10, jobs=1, seed=3, max_s=60.0)
pytestmark = pytest.mark.timeout(900)
TRUE_THRESHOLD_N_M = {"outsider": 0.0050, "novice": 0.0036, "expert": 0.0026}
"""Set apart from the profiles' 0.0041 / 0.0037 / 0.0033."""
TRUE_COMFORT_N_M = {"outsider": 0.012, "novice": 0.009, "expert": 0.007}
"""The profiles': 0.010 / 0.009 / 0.008."""
PROBE_TRIALS = {
    "reaction_time": 20,
    "force_threshold": 100,
    "stall_detection": 20,
    "aiming": 30,
    "comfort_torque": 8,
}
"""With 6 people a group, a trait's ratio is below 0.5 only when a person's probe
estimate is more precise than the group's spread (information > 1 prior variance): the
force threshold needs 100 two-interval trials for that with the experts."""


def _truth() -> dict:
    return {
        g: [
            dataclasses.replace(
                p,
                haptic_threshold_n_m=(TRUE_THRESHOLD_N_M[g], 0.0004),
                comfort_torque_n_m=(TRUE_COMFORT_N_M[g], 0.0008),
            )
        ]
        for g, p in PROFILES.items()
    }


def _people(seed: int, per_group: int) -> dict[str, object]:
    """The people `simulate_people` draws (its rng and order), by their codes S001..."""
    rng = np.random.default_rng([seed, 0xC4EC])
    people = [
        draw_traits(g, rng, {g: ps[0]}) for g, ps in _truth().items() for _ in range(per_group)
    ]
    return {f"S{i + 1:03d}": t for i, t in enumerate(people)}


def _probe_frame(people: dict[str, object]) -> pd.DataFrame:
    rows = []
    for k, (code, traits) in enumerate(people.items()):
        rng = np.random.default_rng([77, k])
        responder = SimulatedResponder(traits, rng)
        for name in probe_names():
            for t in run_probe(name, PROBE_TRIALS[name], responder, rng, {"gain_n_m_per_n": 0.02}):
                rows.append(
                    (
                        code,
                        t.probe,
                        t.trial_index,
                        t.stimulus,
                        t.response,
                        t.correct,
                        dict(t.context),
                        t.driver,
                    )
                )
    columns = [
        "participant",
        "probe",
        "trial_index",
        "stimulus",
        "response",
        "correct",
        "context",
        "driver",
    ]
    return pd.DataFrame(rows, columns=columns)


@pytest.fixture(scope="module")
def study():
    data = dataclasses.replace(SETTINGS, seed=21)
    trials = simulate_people("lcca", _truth(), 6, 2, data, lambda *_: None)
    people = _people(21, 6)
    assert set(trials["participant"]) == set(people)
    return trials, people, _probe_frame(people)


@pytest.fixture(scope="module")
def emulator():
    return build_emulator("lcca", SETTINGS)


def test_with_probes_every_trait_is_fitted_and_the_probed_ones_recovered(study, emulator):
    trials, people, probe_trials = study
    model, _ = fit_trials(
        trials, "lcca", SETTINGS, emulator, "test data", probes=probe_table(probe_trials)
    )
    assert model["fixed_at_prior"] == []
    assert model["shrunk_to_prior"] == []
    assert set(model["identifiable"]) == set(TRAITS)
    assert all(r < IDENTIFIED_RATIO for r in model["identification_ratio"].values()), model[
        "identification_ratio"
    ]
    assert model["probes"]["missing"] == {}
    assert set(model["probes"]["measured"]) == set(TRAITS) - {"preferred_speed_m_s", "caution"}
    # each group's fitted mean against the mean of its own six people's true values: a
    # group of 6 with 100-trial thresholds carries about 8 % SE on the threshold's mean
    for trait, tolerance in (
        ("haptic_threshold_n_m", 0.25),
        ("comfort_torque_n_m", 0.15),
        ("visual_stall_s", 0.15),
        ("steering_error_rad", 0.25),
    ):
        for group in PROFILES:
            own = np.mean([getattr(t, trait) for t in people.values() if t.group == group])
            got = model["groups"][group][trait]["mean"]
            assert abs(got - own) <= tolerance * own, (trait, group, got, own)


def test_a_participant_missing_a_probe_still_fits_and_the_output_says_so(study, emulator):
    trials, _, probe_trials = study
    lacking = probe_trials[
        ~((probe_trials["participant"] == "S002") & (probe_trials["probe"] == "force_threshold"))
    ]
    model, _ = fit_trials(
        trials, "lcca", SETTINGS, emulator, "test data", probes=probe_table(lacking)
    )
    assert model["probes"]["missing"] == {"S002": ["haptic_threshold_n_m"]}
    assert "S002 lacks haptic_threshold_n_m" in model["probes"]["line"]
    person = model["fit"]["outsider"]["people"]["S002"]
    assert np.isfinite(person["haptic_threshold_n_m"])
    assert model["fixed_at_prior"] == []
