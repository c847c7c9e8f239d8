"""The held-out identification check (`participant_fit.validate`) and the hierarchical
estimator (`participant_fit.estimate`) on a synthetic design whose moments are known
functions of the traits: a trait that moves a moment is told, one that moves none is
not, and the EM recovers a group's mean of a told trait."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from study.analysis.participant_fit.emulator import MomentEmulator, design_box, design_settings
from study.analysis.participant_fit.estimate import HYPER_SD, GroupEstimator
from study.analysis.participant_fit.validate import held_out_errors
from study.protocol.traits import PROFILES, TRAITS

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


def synthetic_trials(
    logs: np.ndarray,
    repeats: int,
    rng: np.random.Generator,
    noise: float | np.ndarray = NOISE,
) -> pd.DataFrame:
    """Trials of the design settings whose log measures are the rows of `logs`: each
    setting `repeats` times in VO and HV, with log-normal noise of SD `noise` (one for
    all, or one per setting and measure, shaped like `logs`)."""
    sds = np.broadcast_to(noise, logs.shape)
    rows = []
    for k, setting_logs in enumerate(logs):
        for r in range(repeats):
            for condition in ("VO", "HV"):
                noisy = np.exp(setting_logs + rng.normal(0.0, 1.0, 2) * sds[k])
                rows.append(
                    {
                        "setting": k,
                        "condition": condition,
                        "repeat": r,
                        **dict(zip(MEASURES, noisy, strict=True)),
                    }
                )
    return pd.DataFrame(rows)


def _trials(x: np.ndarray, repeats: int, rng: np.random.Generator) -> pd.DataFrame:
    return synthetic_trials(_law(x), repeats, rng)


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
            # nothing follows it: the estimate is no better than the wide prior's centre,
            # whose error is the design's own spread about it (the surface's spurious small
            # slopes on the noise can only add to it)
            assert errors[j] > 0.8 * spread[j], trait


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


def test_a_weakly_told_traits_group_mean_is_the_data_and_the_profile_weighted() -> None:
    """A weak trait's group mean has the prior N(profile mean, HYPER_SD profile SDs): the
    EM's fixed point is the normal-normal posterior mean of the people's (conjugate:
    n / sd^2 and 1 / (HYPER_SD sd0)^2 the two weights); a trait no moment follows stays at
    the profile."""
    rng = np.random.default_rng(3)
    x = design_settings(200, 1, design_box())
    emulator = MomentEmulator().fit(x, _trials(x, 2, rng), MEASURES)
    speed, reaction = TRAITS.index("preferred_speed_m_s"), TRAITS.index("reaction_s")
    people = np.tile([getattr(PROFILES["novice"], t)[0] for t in TRAITS], (12, 1))
    people[:, speed] = rng.normal(0.010, 0.002, 12)
    y = np.column_stack([_law(people)] * 2) + rng.normal(0.0, NOISE / np.sqrt(3), (12, 4))
    free = [speed, reaction]
    weak = GroupEstimator(emulator, PROFILES["novice"], free, 3.0, weak=free).fit(y)
    alone = GroupEstimator(emulator, PROFILES["novice"], free, 3.0).fit(y)
    # fitted freely, a trait nothing tells (the reaction time here) drifts along a flat
    # likelihood and need not converge within EM_STEPS (it does not on the design box of
    # the profiles whose haptic thresholds are centred on the JND); under its prior it does
    assert weak.success
    m0, s0 = PROFILES["novice"].preferred_speed_m_s
    s, n = weak.sd[speed], len(y)
    expected = (n / s**2 * weak.people[:, speed].mean() + m0 / (HYPER_SD * s0) ** 2) / (
        n / s**2 + 1 / (HYPER_SD * s0) ** 2
    )
    assert weak.mean[speed] == pytest.approx(expected, rel=2e-3)
    # between the people's mean and the profile's, much nearer the people's (12 of them)
    assert alone.mean[speed] < weak.mean[speed] < m0
    assert weak.mean[speed] - alone.mean[speed] < 0.2 * (m0 - alone.mean[speed])
    # nothing but the surface's small spurious slopes tells the reaction time: under its
    # prior it keeps nearer the profile than fitted freely, within one profile SD
    r0, r_sd = PROFILES["novice"].reaction_s
    assert abs(weak.mean[reaction] - r0) < abs(alone.mean[reaction] - r0), alone.mean[reaction]
    assert abs(weak.mean[reaction] - r0) < r_sd


def test_a_weak_traits_bootstrap_holds_its_priors_uncertainty() -> None:
    """Nothing tells the reaction time here: its posterior is its prior, N(profile mean,
    HYPER_SD profile SDs). Replicates that resample the people and draw the prior's
    centre (`prior_centre`) spread by about that SD; resampling the people alone would
    leave a shrunk mean's interval near zero width."""
    rng = np.random.default_rng(4)
    x = design_settings(200, 1, design_box())
    emulator = MomentEmulator().fit(x, _trials(x, 2, rng), MEASURES)
    speed, reaction = TRAITS.index("preferred_speed_m_s"), TRAITS.index("reaction_s")
    people = np.tile([getattr(PROFILES["novice"], t)[0] for t in TRAITS], (12, 1))
    y = np.column_stack([_law(people)] * 2) + rng.normal(0.0, NOISE / np.sqrt(3), (12, 4))
    est = GroupEstimator(emulator, PROFILES["novice"], [speed, reaction], 3.0, weak=[reaction])
    drawn, resampled = [], []
    for _ in range(16):
        rows = y[rng.integers(0, 12, 12)]
        drawn.append(est.fit(rows, None, est.prior_centre(rng)).mean[reaction])
        resampled.append(est.fit(rows).mean[reaction])
    s0 = PROFILES["novice"].reaction_s[1]
    # 16 draws: the SD of their SD is about 18 %
    assert np.std(drawn, ddof=1) == pytest.approx(HYPER_SD * s0, rel=0.45)
    assert np.std(resampled, ddof=1) < 0.3 * s0


def test_the_surfaces_terms_in_numpy_equal_scikit_learns() -> None:
    """`MomentEmulator.terms` (plain numpy, for speed) against scikit-learn's pipeline of
    the same steps (log traits but the caution, standardised, quadratic terms)."""
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import FunctionTransformer, PolynomialFeatures, StandardScaler

    from study.analysis.participant_fit.emulator import surface_traits

    rng = np.random.default_rng(5)
    x = design_settings(60, 2, design_box())
    emulator = MomentEmulator().fit(x, _trials(x, 2, rng), MEASURES)
    reference = make_pipeline(
        FunctionTransformer(surface_traits), StandardScaler(), PolynomialFeatures(2)
    ).fit(x)  # the design rows repeat each setting equally often: the same scaling
    probe = design_settings(15, 3, design_box())
    np.testing.assert_allclose(emulator.terms(probe), reference.transform(probe), atol=1e-12)
    assert emulator.terms(probe).shape == (15, 36)  # 1 + 7 + 28 terms of degree <= 2


def _linear_emulator(slope: float, within: float, misfit: float) -> MomentEmulator:
    """One moment (per condition) = `slope` x log(preferred speed), nothing else: a
    surface of degree 1 on the log traits, unscaled, with the given trial scatter and
    misfit (variances, log scale)."""
    from sklearn.preprocessing import PolynomialFeatures

    em = MomentEmulator(degree=1)
    em.moments_ = ["VO:completion_time_s", "HV:completion_time_s"]
    em.measures_, em.features_ = ["completion_time_s"], []
    em.centre_, em.scale_ = np.zeros(len(TRAITS)), np.ones(len(TRAITS))
    em.powers_ = PolynomialFeatures(1).fit(np.zeros((1, len(TRAITS)))).powers_
    em.coef_ = np.zeros((len(TRAITS) + 1, 2))
    em.coef_[1 + TRAITS.index("preferred_speed_m_s")] = slope
    em.intercept_ = np.zeros(2)
    em.within_var_, em.misfit_var_ = np.full(2, within), np.full(2, misfit)
    em.defined_ = np.ones(2)
    return em


def test_a_traits_held_out_information_grows_with_the_studys_trials_per_condition() -> None:
    from study.analysis.participant_fit.estimate import identifiable

    # the speed moves both moments by -1 in log per log (a trial's time ~ 1 / speed);
    # per person with k trials: noise var w / k + m on each of the two moments
    w, m, n = 0.04, 0.001, 8
    em = _linear_emulator(-1.0, w, m)
    profile = PROFILES["novice"]
    mu, sd = profile.preferred_speed_m_s
    sizes = {"novice": np.full(2, n)}
    held_error = 2.0 * sd  # a held-out person with 2 trials: twice the prior SD off
    speed = "preferred_speed_m_s"

    def ratio(k: float, held_k: float | None) -> float:
        return identifiable(
            em, {"novice": profile}, sizes, {"novice": k}, np.full(len(TRAITS), held_error), held_k
        )[1][speed]

    def by_hand(info: float) -> float:
        # a group of n people N(mu, 1) (prior SDs), each with information `info`
        return 1.0 / np.sqrt(1.0 + n * info / (1.0 + info))

    # d moment / d (speed in prior SDs) = -sd / mu at the prior mean, on two moments
    linear = lambda k: 2 * (sd / mu) ** 2 / (w / k + m)  # noqa: E731
    held_info = (sd / held_error) ** 2
    # the held-out people had 2 trials: at k = 2 their information counts as it is, and
    # it is the larger ratio (the slopes promise more)
    assert by_hand(held_info) > by_hand(linear(2))
    assert ratio(2, 2.0) == pytest.approx(by_hand(held_info), rel=1e-6)
    # at k = 8 it grows as the linearised information does from 2 to 8 trials
    grown = held_info * linear(8) / linear(2)
    assert ratio(8, 2.0) == pytest.approx(max(by_hand(grown), by_hand(linear(8))), rel=1e-6)
    assert ratio(8, 2.0) < ratio(2, 2.0)
    # without a held-out k, the held-out error is taken as the study's own (as before)
    assert ratio(8, None) == pytest.approx(by_hand(held_info), rel=1e-6)
