"""The analysis' own distribution functions and tests against R (values quoted) and scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize, stats

from study.analysis.distributions import (
    brentq,
    f_sf,
    norm_sf,
    rank_average,
    shapiro_wilk,
    signed_rank_exact_p,
    signed_rank_normal_p,
    t_ppf,
    t_sf,
    t_two_sided,
)
from tests.study.conftest import modules_loaded

# R 4.2.2: set.seed(7); x <- round(rexp(n), 3); shapiro.test(x) -> W, p (15 digits)
R_SHAPIRO = [
    ([0.048, 1.622, 1.713], 0.790861874384507, 0.0928645582466664),
    ([0.812, 0.546, 2.620, 0.752], 0.737356464426223, 0.0291979973851498),
    ([4.273, 0.205, 0.046, 0.944, 0.748], 0.742327692002858, 0.0252324767298707),
    ([1.872, 1.867, 1.210, 0.345, 0.677, 0.958, 0.519], 0.89788611167984, 0.318372570007625),
    (
        [0.915, 2.401, 0.633, 0.397, 0.440, 0.548, 0.256, 0.446, 1.240, 1.689, 1.884],
        0.86787847003899,
        0.0727988900190055,
    ),
    (
        [1.258, 0.789, 1.922, 0.009, 0.528, 0.387, 0.088, 0.318, 0.927, 0.892, 0.681, 0.242],
        0.927785504119953,
        0.357230192952343,
    ),
    (
        [
            1.463,
            0.135,
            0.997,
            0.609,
            1.441,
            2.597,
            0.524,
            1.085,
            1.360,
            1.069,
            4.235,
            0.126,
            0.144,
            0.080,
            1.113,
            0.648,
            1.875,
            1.279,
            0.961,
            1.068,
        ],
        0.825625365049135,
        0.00213777562542028,
    ),
]


@pytest.mark.parametrize(("x", "w", "p"), R_SHAPIRO)
def test_shapiro_wilk_equals_r(x: list[float], w: float, p: float) -> None:
    got_w, got_p = shapiro_wilk(np.array(x))
    assert got_w == pytest.approx(w, rel=1e-13)
    assert got_p == pytest.approx(p, rel=1e-12)  # scipy's own is 1e-8 off R's


def test_shapiro_wilk_is_scipy_within_its_distance_from_r() -> None:
    rng = np.random.default_rng(3)
    for n in (3, 4, 5, 6, 9, 12, 20, 36, 60):
        for power in (1, 2, 3):
            x = rng.standard_normal(n) ** power
            w, p = shapiro_wilk(x)
            ref = stats.shapiro(x)
            assert w == pytest.approx(ref.statistic, rel=1e-8), n
            assert p == pytest.approx(ref.pvalue, rel=1e-6, abs=1e-12), n


def test_distribution_functions_equal_r() -> None:
    # R 4.2.2: qt(0.975, 7); pt(-3.2, 19); pf(4.7, 3, 33, lower.tail = FALSE);
    #          pf(62.2, 1, 33, lower.tail = FALSE)
    assert t_ppf(0.975, 7) == pytest.approx(2.36462425159278, rel=1e-13)
    assert t_sf(3.2, 19) == pytest.approx(0.00235709451413159, rel=1e-13)
    assert f_sf(4.7, 3, 33) == pytest.approx(0.007695525191905, rel=1e-12)
    assert f_sf(62.2, 1, 33) == pytest.approx(4.29954981438651e-09, rel=1e-12)


@pytest.mark.parametrize("df", [1, 2, 3, 5, 7, 19, 33, 35, 100, 1000])
def test_t_and_f_equal_scipy_in_both_tails(df: int) -> None:
    for t in (-40.0, -3.0, -0.3, 0.0, 0.2, 1.96, 5.0, 30.0, 200.0):
        assert t_sf(t, df) == pytest.approx(stats.t.sf(t, df), rel=1e-11), t
        assert t_two_sided(t, df) == pytest.approx(2 * stats.t.sf(abs(t), df), rel=1e-11), t
    for q in (0.5, 0.6, 0.9, 0.975, 0.995, 0.025):
        assert t_ppf(q, df) == pytest.approx(stats.t.ppf(q, df), rel=1e-12, abs=1e-300), q
    for df1 in (1, 2, 3, 5):
        for f in (0.0, 0.01, 0.5, 1.0, 3.0, 10.0, 62.0, 500.0, 1e4):
            assert f_sf(f, df1, df) == pytest.approx(stats.f.sf(f, df1, df), rel=1e-11), f
    assert f_sf(math.inf, 2, df) == 0.0
    assert math.isnan(f_sf(math.nan, 2, df))


def test_normal_tail_keeps_its_digits() -> None:
    for z in (-5.0, -1.0, 0.0, 1.0, 3.0, 8.0, 20.0):
        assert norm_sf(z) == pytest.approx(stats.norm.sf(z), rel=1e-13)


def test_signed_rank_p_equals_scipy() -> None:
    rng = np.random.default_rng(5)
    for n in range(1, 30):
        d = rng.standard_normal(n)
        ranks = rank_average(np.abs(d))
        exact = signed_rank_exact_p(ranks[d > 0].sum(), n)
        assert exact == pytest.approx(stats.wilcoxon(d, method="exact").pvalue, rel=1e-14)
        tied = np.round(d, 1)
        tied = tied[tied != 0]
        if tied.size > 1:
            ranks = rank_average(np.abs(tied))
            assert np.array_equal(ranks, stats.rankdata(np.abs(tied)))
            ref = stats.wilcoxon(tied, method="asymptotic", correction=True).pvalue
            assert signed_rank_normal_p(ranks, ranks[tied > 0].sum()) == pytest.approx(
                ref, rel=1e-13
            )
    # R 4.2.2: psignrank(3, 10) * 2 = 0.009765625 (V = 3 of n = 10: 10 of 1024 subsets)
    assert signed_rank_exact_p(3, 10) == 0.009765625


def test_brentq_takes_scipys_iterates() -> None:
    for f, a, b in ((lambda x: math.cos(x) - x, 0.0, 2.0), (lambda x: x**3 - 2, 0.0, 4.0)):
        mine = brentq(f, a, b, xtol=1e-300, rtol=1e-15)
        assert mine == optimize.brentq(f, a, b, xtol=1e-300, rtol=1e-15)


def test_study_analyze_loads_no_scipy() -> None:
    code = "import study.commands.analyze, study.analysis.stats, study.analysis.report"
    assert modules_loaded(code, ("scipy",)) == []
