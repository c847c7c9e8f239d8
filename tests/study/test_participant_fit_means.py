"""The emulator's group means on the measures' own scale (`MomentEmulator.means`), and
the emulator check's comparison (`checks.emulator_check`, `fit.replicate_prediction`).

The means are held to closed forms: a trial's measure log-normal about a known law, so
its mean is exp(law + s^2 / 2), with a spread s that follows a trait (as the peak
forces' does). The Newton solver of the mean surface is held to scikit-learn's
`PoissonRegressor` on the same objective.
The emulator check's interval counts the emulator's own noise (its design's, by refits
to resampled designs) beside the simulated people's: held to the nominal 5 % on toy
emulators whose truth is the closed form, and to flagging a biased one."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import statsmodels.api as sm
from sklearn.linear_model import PoissonRegressor

from study.analysis.participant_fit.checks import emulator_check
from study.analysis.participant_fit.emulator import (
    LOG_LINK,
    LOGIT_LINK,
    MomentEmulator,
    design_box,
    design_settings,
    glm_ridge,
    poisson_ridge,
)
from study.analysis.participant_fit.fit import replicate_design_sd, replicate_prediction
from study.analysis.participant_fit.observed import bootstrap_means
from study.protocol.traits import TRAITS
from tests.study.test_participant_fit_validate import MEASURES, synthetic_trials


def _law(traits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(log medians, log SDs) of people with `traits`: the time follows the preferred
    speed with a 5 % spread; the force's median the caution a little, its spread the
    caution a lot (SD 0.2 at caution 0 to 1.0 at caution 1)."""
    speed = traits[:, TRAITS.index("preferred_speed_m_s")]
    caution = traits[:, TRAITS.index("caution")]
    logs = np.column_stack([np.log(0.25 / speed), -1.0 + 0.2 * caution])
    sds = np.column_stack([np.full(len(traits), 0.05), 0.2 + 0.8 * caution])
    return logs, sds


def _true_means(traits: np.ndarray) -> np.ndarray:
    """The log-normal mean exp(mu + s^2 / 2) of each measure, VO then HV."""
    logs, sds = _law(traits)
    return np.tile(np.exp(logs + sds**2 / 2), 2)


def test_the_means_follow_a_spread_that_moves_with_the_traits() -> None:
    x = design_settings(1000, 11, design_box())
    logs, sds = _law(x)
    trials = synthetic_trials(logs, 2, np.random.default_rng(11), sds)
    emulator = MomentEmulator().fit(x, trials, MEASURES)
    smeared = MomentEmulator(mean_surface=False).fit(x, trials, MEASURES)
    # people at low, middle and high caution (a fifth of the box from its ends), the
    # other traits at the box's centre
    low, high = design_box()
    probe = np.tile((low + high) / 2, (3, 1))
    c = TRAITS.index("caution")
    probe[:, c] = low[c] + np.array([0.2, 0.5, 0.8]) * (high[c] - low[c])
    truth = _true_means(probe)
    force = [i for i, n in enumerate(emulator.moments_) if n.endswith("force_n")]
    new = emulator.means(probe)[:, force] / truth[:, force] - 1
    old = smeared.means(probe)[:, force] / truth[:, force] - 1
    # one smearing factor for every caution is the design's average exp(s^2 / 2): too
    # large where the spread is small, too small where it is large (in VO and HV)
    assert (old[0] > 0.1).all(), old
    assert (old[2] < -0.1).all(), old
    # the mean surface: within the noise of 2000 log-normal trials of SD up to 1
    assert np.abs(new).max() < 0.08, new
    # the time's spread is the same everywhere: both agree with the closed form
    time = [i for i, n in enumerate(emulator.moments_) if n.endswith("time_s")]
    for e in (emulator, smeared):
        np.testing.assert_allclose(e.means(probe)[:, time], truth[:, time], rtol=0.01)


def test_the_newton_solver_finds_scikit_learns_poisson_fit() -> None:
    rng = np.random.default_rng(2)
    phi = rng.normal(size=(300, 6))
    y = rng.gamma(2.0, np.exp(0.2 + phi[:, :2] @ [0.4, -0.3]) / 2.0)
    for alpha in (1e-3, 0.1):
        coef, intercept = poisson_ridge(phi, y, np.ones(len(y)), alpha)
        ref = PoissonRegressor(alpha=alpha, tol=1e-12, max_iter=10_000).fit(phi, y)
        np.testing.assert_allclose(coef, ref.coef_, atol=1e-6)
        assert abs(intercept - ref.intercept_) < 1e-6
    # weights: a trial of weight 2 is the same trial twice
    w = np.where(np.arange(len(y)) < 100, 2.0, 1.0)
    twice = np.concatenate([np.arange(len(y)), np.arange(100)])
    a = poisson_ridge(phi, y, w, 1e-3)
    b = poisson_ridge(phi[twice], y[twice], np.ones(len(twice)), 1e-3)
    np.testing.assert_allclose(a[0], b[0], atol=1e-8)


def test_the_newton_solver_with_the_logit_link_finds_statsmodels_logistic_fit() -> None:
    # unpenalised, unweighted: the maximum-likelihood logistic regression
    rng = np.random.default_rng(5)
    phi = rng.normal(size=(400, 4))
    eta = -0.3 + phi @ [0.8, -0.5, 0.0, 0.3]
    y = (rng.uniform(size=len(eta)) < 1 / (1 + np.exp(-eta))).astype(float)
    coef, intercept = glm_ridge(phi, y, np.ones(len(y)), 0.0, LOGIT_LINK)
    ref = sm.Logit(y, sm.add_constant(phi)).fit(method="newton", tol=1e-12, disp=False)
    np.testing.assert_allclose(np.r_[intercept, coef], ref.params, atol=1e-6)


def test_the_newton_solver_with_the_log_link_finds_the_closed_form_of_one_group() -> None:
    # one 0/1 term: the unpenalised Poisson fit's means are the two groups' means
    x = np.repeat([0.0, 1.0], [3, 5])
    y = np.array([1.0, 2.0, 6.0, 10.0, 20.0, 30.0, 40.0, 50.0])
    coef, intercept = glm_ridge(x[:, None], y, np.ones(len(y)), 0.0, LOG_LINK)
    assert abs(intercept - np.log(3.0)) < 1e-9
    assert abs(coef[0] - np.log(30.0 / 3.0)) < 1e-9


def test_the_check_compares_the_people_simulated_with_the_population_they_came_from() -> None:
    # person i of a group comes from replicate i mod 3: with 4 people, replicates 1, 2,
    # 3, 1 (index 0 is the best fit): (2 + 4 + 6 + 2) / 4 = 3.5
    assert replicate_prediction([10.0, 2.0, 4.0, 6.0], 4) == 3.5
    assert replicate_prediction([10.0], 4) == 10.0
    rows = [
        ("novice", "t", "VO", "simulated", 10.0, 9.0, 11.0),
        ("novice", "t", "VO", "model", 12.0, 0, 0),
        ("expert", "t", "VO", "simulated", 8.0, 7.5, 8.5),
        ("expert", "t", "VO", "model", 8.2, 0, 0),
    ]
    table = pd.DataFrame(
        rows, columns=["group", "measure", "condition", "source", "mean", "ci_low", "ci_high"]
    )
    # at the best fit the novices' 12.0 lies outside; for the replicates' people, 10.4
    # inside, and the experts' 8.9 outside
    check = emulator_check(table, {("novice", "t", "VO"): 10.4, ("expert", "t", "VO"): 8.9})
    assert [r["inside"] for r in check["rows"]] == [True, False]
    assert [r["inside_best_fit"] for r in check["rows"]] == [False, True]
    assert (check["outside"], check["outside_best_fit"]) == (1, 1)
    assert "largest gap: expert VO t 8.9 vs 8)" in check["line"]


SETTINGS = 200
"""The toy emulators' design: settings, one trial a condition each."""


def _toy_check(design_seed: int, bias: float, people: int = 60) -> dict:
    """The emulator check of one toy emulator (`SETTINGS` design settings, one trial a condition,
    the log-normal law above) for a group centred in the design's box, against `people`
    people of that group (3 trials a condition, traits drawn from the same population,
    trials from the law): the emulator's predictions times `1 + bias`."""
    rng = np.random.default_rng([design_seed, 7])
    low, high = design_box()
    x = design_settings(SETTINGS, design_seed, (low, high))
    design_logs, design_sds = _law(x)
    trials = synthetic_trials(design_logs, 1, rng, design_sds)
    emulator = MomentEmulator().fit(x, trials, MEASURES)
    mean, sd = (low + high) / 2, (high - low) / 12
    z = np.random.default_rng(3).standard_normal((2000, len(TRAITS)))
    est = SimpleNamespace(emulator=emulator, draws=lambda m, s: np.clip(m + s * z, low, high))
    result = SimpleNamespace(estimator=est, boots=np.array([np.concatenate([mean, sd])]), fit=None)
    design_sd = replicate_design_sd(result, people, MEASURES)
    predicted = emulator.means(est.draws(mean, sd)).mean(axis=0) * (1 + bias)
    pred = dict(zip(emulator.moments_, predicted, strict=True))
    # the simulated people: their own traits, 3 trials a condition from the law
    own = np.clip(mean + sd * rng.standard_normal((people, len(TRAITS))), low, high)
    logs, sds = _law(own)
    rows, for_simulated, noise = [], {}, {}
    per = {c: np.zeros((people, len(MEASURES))) for c in ("VO", "HV")}
    for c in per:
        per[c] = np.exp(logs[:, None] + sds[:, None] * rng.standard_normal((people, 3, 2))).mean(1)
    for j, m in enumerate(MEASURES):
        for label in ("VO", "HV", "HV-VO"):
            v = per["HV"][:, j] - per["VO"][:, j] if label == "HV-VO" else per[label][:, j]
            p = pred[f"HV:{m}"] - pred[f"VO:{m}"] if label == "HV-VO" else pred[f"{label}:{m}"]
            lo, hi = bootstrap_means(v, rng, 400)
            rows += [
                ("g", m, label, "simulated", v.mean(), lo, hi),
                ("g", m, label, "model", p, 0, 0),
            ]
            for_simulated[("g", m, label)] = p
            noise[("g", m, label)] = design_sd[(m, label)]
    table = pd.DataFrame(
        rows, columns=["group", "measure", "condition", "source", "mean", "ci_low", "ci_high"]
    )
    return emulator_check(table, for_simulated, noise)


def test_the_check_counts_the_emulators_own_noise_and_flags_a_bias() -> None:
    # unbiased toy emulators: their own noise (a quadratic surface on 200 settings) is
    # larger than 60 people's SE, so the people's interval alone flags them far beyond
    # 5 % of the time; with the design's noise counted, about 5 % (24 designs x 6
    # summaries: the count's SD at 5 % is 2.6 of 144)
    checks = [_toy_check(seed, 0.0) for seed in range(24)]
    both = sum(c["outside"] for c in checks) / (6 * len(checks))
    people_only = sum(c["outside_people_only"] for c in checks) / (6 * len(checks))
    assert 0.01 <= both <= 0.10, both
    assert people_only > 3 * both, (people_only, both)
    assert all("design noise" in c["interval"] for c in checks)
    # an emulator 15 % high: the completion time (5 % spread a trial) is flagged in VO
    # and HV on every design, its own noise counted
    for c in [_toy_check(seed, 0.15) for seed in range(6)]:
        time = {r["condition"]: r["inside"] for r in c["rows"] if r["measure"] == MEASURES[0]}
        assert not time["VO"], c["rows"]
        assert not time["HV"], c["rows"]
