"""A simulated person's repeated trials vary as measured trials do: no two measured
trials of a block are equal in a measure that is not quantised, and the phantom's
per-trial contact conditions have the distribution their parameters state."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from study.campaign.unit import trial_seed
from study.protocol.tasks import get_task
from study.protocol.traits import simulated_participant
from study.protocol.trial_run import simulate_trial
from study.tasks.lcca.simulated_participant import SimulatedParticipant
from teleop_core.errors import TeleopInputError
from teleop_core.phantom.lcca import H_DISTAL_OFFSET, H_LTIP, GuidewireParams, LccaPhantom

CONTINUOUS = ("peak_proximal_force_n", "peak_proximal_reference_force_n", "peak_distal_force_n")
"""The LCCA trial's measures that are not quantised (forces, stored as floats)."""
N_DRAWS = 1000
"""Trial draws of the contact conditions checked against their distribution."""
DECISION_S = 1.0 / SimulatedParticipant.rate_hz
"""Completion time is quantised: a trial ends on one of the participant's decisions."""


def test_no_two_trials_of_a_block_are_equal() -> None:
    phantom = LccaPhantom()
    for group, condition in itertools.product(("outsider", "novice", "expert"), ("VO", "HV")):
        code = f"P{group[0]}"
        person = simulated_participant(group, 3)
        block = 1 if condition == "VO" else 2
        summaries = [
            simulate_trial(
                get_task("lcca"),
                person,
                condition,
                trial_seed(7, code, block, i),
                90.0,
                context=phantom,
            ).summary
            for i in range(3)
        ]
        for measure in CONTINUOUS:
            values = [s[measure] for s in summaries]
            assert len(set(values)) == len(values), (group, condition, measure, values)
        for s in summaries:
            ticks = s["completion_time_s"] / DECISION_S
            assert ticks == pytest.approx(round(ticks), abs=1e-6)


def test_trial_contact_conditions_follow_their_distribution() -> None:
    wire = GuidewireParams()
    phantom = LccaPhantom()
    nominal = phantom.params()
    draws = np.array([phantom.trial_params(seed) for seed in range(N_DRAWS)])
    load = nominal[H_LTIP] / draws[:, H_LTIP]  # the bearing load's factor, EI kappa / l_tip
    # lognormal of mean 1 and CV tip_load_cv: SE of the mean cv / sqrt(n) = 0.0032, of
    # an SD about 2.2 % of it
    assert load.mean() == pytest.approx(1.0, abs=0.013)
    assert load.std() / load.mean() == pytest.approx(wire.tip_load_cv, rel=0.1)
    assert np.log(load).std() == pytest.approx(math.sqrt(math.log1p(wire.tip_load_cv**2)), rel=0.1)
    offset = draws[:, H_DISTAL_OFFSET]
    assert offset.mean() == pytest.approx(0.0, abs=4 * wire.distal_offset_sd_n / math.sqrt(N_DRAWS))
    assert offset.std() == pytest.approx(wire.distal_offset_sd_n, rel=0.1)
    # everything else is the nominal phantom; one seed, one draw
    others = [i for i in range(nominal.size) if i not in (H_LTIP, H_DISTAL_OFFSET)]
    assert np.array_equal(
        draws[:, others], np.broadcast_to(nominal[others], (N_DRAWS, len(others)))
    )
    assert np.array_equal(phantom.trial_params(5), phantom.trial_params(5))


def test_nominal_environment_has_no_offset() -> None:
    params = LccaPhantom().environment().params
    assert params[H_DISTAL_OFFSET] == 0.0
    assert params[H_LTIP] == GuidewireParams().tip_length_m


def test_negative_spread_is_refused() -> None:
    with pytest.raises(TeleopInputError, match="tip_load_cv"):
        GuidewireParams(tip_load_cv=-0.1)
