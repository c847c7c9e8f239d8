"""NOTES trials vary from trial to trial as LCCA's do: the person's state per trial and
the tissue as the trial meets it, so no two trials of a block share a peak force or
torque and the mixed model does not count copies as independent trials."""

from __future__ import annotations

import math

import numpy as np
import pytest

from study.protocol.design import MAX_TRIAL_S
from study.protocol.tasks import get_task
from study.protocol.traits import TRIAL_CV, simulated_participant
from study.protocol.trial_run import simulate_trial
from teleop_core.notes import tissue
from teleop_core.notes.task import TISSUE, NotesLoop

NOTES = get_task("notes")


def test_a_trials_tissue_varies_about_the_nominal_with_the_stated_cv() -> None:
    draws = [TISSUE.for_trial(np.random.default_rng(seed)) for seed in range(4000)]
    for name, cv in tissue.TRIAL_CV.items():
        factors = np.array([getattr(d, name) for d in draws]) / getattr(TISSUE, name)
        # lognormal of mean 1 and CV cv: the sample's mean within 4 SE, its CV within 10 %
        assert factors.mean() == pytest.approx(1.0, abs=4 * cv / math.sqrt(len(draws)))
        assert factors.std(ddof=1) == pytest.approx(cv, rel=0.1)
    # the rest of the tissue is the nominal one
    fixed = {"fornix_depth_m", "fold_depth_m", "scope_radius_m", "ccw_transmission"}
    assert all(getattr(draws[0], name) == getattr(TISSUE, name) for name in fixed)


def test_the_trials_seed_sets_its_tissue_and_a_given_tissue_is_kept() -> None:
    a, b, c = NotesLoop(True, seed=5), NotesLoop(True, seed=5), NotesLoop(True, seed=6)
    assert a.abdomen.params == b.abdomen.params
    assert a.abdomen.params != c.abdomen.params
    assert NotesLoop(True, seed=5, tissue=TISSUE).abdomen.params == TISSUE


def test_no_two_trials_of_a_block_share_a_peak_and_the_person_state_is_recorded() -> None:
    person = simulated_participant("novice", 7)
    for condition in ("VO", "HV"):
        block = [
            simulate_trial(NOTES, person, condition, seed, MAX_TRIAL_S).summary
            for seed in (101, 102, 103)
        ]
        for measure in ("peak_push_n", "peak_torque_demanded_n_m", "peak_tip_force_n"):
            values = [s[measure] for s in block]
            assert len(set(values)) == 3, (condition, measure, values)
        states = [s["trial_state"] for s in block]
        for trait in TRIAL_CV:
            assert len({state[trait] for state in states}) == 3, trait
        assert all(s["participant"] == block[0]["participant"] for s in block)
