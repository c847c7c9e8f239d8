"""Each group's own emulator (`MomentEmulator.local`) on a synthetic design whose moments
are known functions of the traits: where the law is not quadratic over the design's
range, the surface fitted to the settings near a group's prior predicts the group's
centre closer to the law than the one global surface; with equal weights it is the
global surface."""

from __future__ import annotations

import numpy as np
import pandas as pd

from study.analysis.participant_fit.emulator import (
    MomentEmulator,
    design_box,
    design_settings,
    group_design_settings,
)
from study.analysis.participant_fit.estimate import prior_arrays
from study.protocol.traits import PROFILES, TRAITS, GroupProfile
from tests.study.test_participant_fit_validate import MEASURES, NOISE, synthetic_trials

"""SD of a trial's log measure about its law."""


def _law(traits: np.ndarray) -> np.ndarray:
    """Log measures of people with `traits`: the time follows the preferred speed; the
    force the caution along a wave no quadratic follows over caution 0.1-0.9."""
    speed = traits[:, TRAITS.index("preferred_speed_m_s")]
    caution = traits[:, TRAITS.index("caution")]
    return np.column_stack([np.log(0.25 / speed), 0.3 * np.sin(8.0 * caution) - 1.0])


def _trials(x: np.ndarray, rng: np.random.Generator) -> pd.DataFrame:
    return synthetic_trials(_law(x), 2, rng)


def _errors(emulator: MomentEmulator, centre: np.ndarray) -> np.ndarray:
    """|log predicted mean - log true mean| of each moment at `centre`: the true mean of
    a trial's measure is exp(law + NOISE^2 / 2) (log-normal noise)."""
    truth = np.tile(_law(centre[None])[0], 2) + NOISE**2 / 2
    return np.abs(np.log(emulator.means(centre[None])[0]) - truth)


def test_a_groups_own_surface_predicts_its_centre_closer_than_the_global_one() -> None:
    x = design_settings(300, 3, design_box())
    emulator = MomentEmulator().fit(x, _trials(x, np.random.default_rng(3)), MEASURES)
    force = [i for i, n in enumerate(emulator.moments_) if n.endswith("force_n")]
    for group, profile in PROFILES.items():
        centre = prior_arrays(profile)[0]
        local = _errors(emulator.local(profile), centre)[force]
        overall = _errors(emulator, centre)[force]
        # the wave over the group's share of the design (its caution's prior SD widened
        # 2.5 times) bends less than over the whole range, so a quadratic follows it
        # closer there
        assert local.max() < 0.75 * overall.max(), group
        # the time's law is what a quadratic in the log speed fits exactly: both
        # surfaces predict it within the trials' noise over the effective settings
        time = [i for i, n in enumerate(emulator.moments_) if n.endswith("time_s")]
        assert _errors(emulator.local(profile), centre)[time].max() < 0.02, group


def test_equal_weights_give_the_global_surface() -> None:
    x = design_settings(120, 4, design_box())
    trials = _trials(x, np.random.default_rng(4))
    emulator = MomentEmulator().fit(x, trials, MEASURES)
    # a prior this wide weighs the design's settings equally (within 1e-9)
    mean, sd = prior_arrays(PROFILES["novice"])
    wide = GroupProfile(
        **{t: (float(m), float(1e6 * s)) for t, m, s in zip(TRAITS, mean, sd, strict=True)}
    )
    local = emulator.local(wide)
    probe = design_settings(20, 5, design_box())
    np.testing.assert_allclose(local.means(probe), emulator.means(probe), rtol=1e-6)
    np.testing.assert_allclose(local.noise_cov_, emulator.noise_cov_, rtol=1e-6)
    np.testing.assert_allclose(local.misfit_var_, emulator.misfit_var_, rtol=1e-6, atol=1e-12)


def test_the_group_design_centres_each_groups_share_on_its_prior() -> None:
    x, owner = group_design_settings(300, 1)
    low, high = design_box()
    assert len(x) == 300
    assert (x >= low).all()
    assert (x <= high).all()
    for g, profile in enumerate(PROFILES.values()):
        mean, sd = prior_arrays(profile)
        mine = x[owner == g]
        assert len(mine) == 100
        # a Latin hypercube of normal quantiles: its median is the prior mean (within
        # a tenth of an SD, as 100 strata sit symmetric about it)
        assert np.all(np.abs(np.median(mine, axis=0) - mean) < 0.1 * sd)
