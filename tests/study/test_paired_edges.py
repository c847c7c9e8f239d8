"""The paired comparison at the edges real data reach, against R (calls quoted)."""

from __future__ import annotations

import numpy as np
import pytest

from study.analysis.comparisons import comparison_rows
from study.analysis.paired import dz_interval, paired_comparison
from study.analysis.signed_rank import signed_rank
from study.analysis.success import success_rows

# R, coin 1.4: ex <- function(d) pvalue(wilcoxsign_test(y ~ x,
#   data = data.frame(y = d, x = 0), distribution = "exact"))


def test_constant_ratings_get_no_t_and_the_exact_signed_rank_p() -> None:
    # ex(c(-5, -5, -5)) -> 0.25; t.test refuses: "data are essentially constant"
    row = paired_comparison(np.array([50.0, 60.0, 70.0]), np.array([45.0, 55.0, 65.0]))
    assert (row["test"], row["p"], row["constant_diff"]) == ("wilcoxon", 0.25, -5.0)
    assert "t" not in row
    assert "shapiro_p" not in row


def test_rounding_noise_does_not_make_a_t_statistic() -> None:
    # d = c(0.5, 0.7, 0.9, 0.3) - c(0.6, 0.8, 1.0, 0.4): -0.1 up to 1e-16 noise;
    # ex(round(d, 10)) -> 0.125
    vo = np.array([0.6, 0.8, 1.0, 0.4])
    row = paired_comparison(vo, np.array([0.5, 0.7, 0.9, 0.3]))
    assert (row["test"], row["p"], row["p_method"]) == ("wilcoxon", 0.125, "exact")


def test_ties_and_zeros_get_the_exact_conditional_p() -> None:
    # ex(c(-5, -5, -10, -10, -5)) -> 0.0625 (wilcox.test's approximation: 0.0533)
    assert signed_rank(np.array([-5.0, -5, -10, -10, -5])).p == 0.0625
    # ex(c(0, -5, -10, -10, -15)) -> 0.125
    assert signed_rank(np.array([0.0, -5, -10, -10, -15])).p == 0.125
    # ex(c(0, 0, 1, 2, 2, -1, 4, 5, 3, 3, -2, 6)) -> 0.029296875
    d = np.array([0.0, 0, 1, 2, 2, -1, 4, 5, 3, 3, -2, 6])
    assert signed_rank(d).p == pytest.approx(0.029296875, abs=1e-15)


def test_sixty_pairs_take_coin_asymptotic() -> None:
    # set.seed(3); d60 <- round(rnorm(60, 0.3, 1), 1)
    # pvalue(wilcoxsign_test(..., distribution = "asymptotic")) -> 0.131037318298877
    # r <- rank(abs(d60)); sum(r[d60 > 0]) -> 1117
    d60 = np.array(
        [
            -0.7,
            0,
            0.6,
            -0.9,
            0.5,
            0.3,
            0.4,
            1.4,
            -0.9,
            1.6,
            -0.4,
            -0.8,
            -0.4,
            0.6,
            0.5,
            0,
            -0.7,
            -0.3,
            1.5,
            0.5,
            -0.3,
            -0.6,
            0.1,
            -1.4,
            -0.2,
            -0.4,
            1.5,
            1.3,
            0.2,
            -0.8,
            1.2,
            1.2,
            1,
            1,
            -0.1,
            1,
            1.6,
            0.3,
            -0.7,
            1.1,
            1.1,
            0,
            2,
            -0.5,
            0.6,
            -2,
            0.1,
            1.4,
            -0.2,
            -0.6,
            1,
            -0.5,
            0.6,
            -1.4,
            -1.1,
            -0.2,
            -0.7,
            1.7,
            1.2,
            -0.5,
        ]
    )
    result = signed_rank(d60)
    assert (result.v, result.method) == (1117.0, "asymptotic")
    assert result.p == pytest.approx(0.131037318298877, rel=1e-10)


def test_t_interval_dz_tost_and_bf10_equal_r() -> None:
    # vo <- c(10, 12, 9, 14, 11, 13); hv <- c(9, 10, 9, 12, 10, 10)
    # t.test(hv, vo, paired = TRUE): t -3.50324524872685, p 0.0172245496803414,
    #   CI -2.600657384708013 -0.399342615291987
    # extractBF(ttestBF(x = hv, y = vo, paired = TRUE))$bf -> 4.58881342358402
    # d <- hv - vo; max(t.test(d, mu = -1, alternative = "greater")$p.value,
    #   t.test(d, mu = 1, alternative = "less")$p.value) -> 0.85222067763273579
    # uniroot(function(ncp) pt(t, 5, ncp) - 0.975 (0.025), ...)$root / sqrt(6)
    #   -> -2.575967474918991, -0.226375318729105
    vo = np.array([10.0, 12, 9, 14, 11, 13])
    hv = np.array([9.0, 10, 9, 12, 10, 10])
    row = paired_comparison(vo, hv, bound=1.0)
    assert row["test"] == "paired_t"
    assert row["statistic"] == pytest.approx(-3.5032452487268531, rel=1e-12)
    assert row["p"] == pytest.approx(0.0172245496803414, rel=1e-10)
    assert row["diff_ci_low"] == pytest.approx(-2.600657384708013, rel=1e-10)
    assert row["diff_ci_high"] == pytest.approx(-0.399342615291987, rel=1e-10)
    assert row["bf10"] == pytest.approx(4.58881342358402, rel=1e-6)
    assert row["tost_p"] == pytest.approx(0.85222067763273579, rel=1e-10)
    assert row["dz_ci_low"] == pytest.approx(-2.575967474918991, rel=1e-8)
    assert row["dz_ci_high"] == pytest.approx(-0.226375318729105, rel=1e-8)


@pytest.mark.parametrize(
    ("t", "n", "low", "high"),
    [
        # R 4.2: ci <- function(t, n) { f <- function(q) uniroot(function(ncp)
        #   pt(t, n - 1, ncp) - q, c(t - 8, t + 8), tol = 1e-13)$root
        #   c(f(0.975), f(0.025)) / sqrt(n) }
        # print(ci(-3.71, 20), digits = 12) -> -1.33211605237 -0.31096321875
        (-3.71, 20, -1.33211605237, -0.31096321875),
        # print(ci(12, 20), digits = 12) -> 1.72241777221 3.62846102590
        (12.0, 20, 1.72241777221, 3.62846102590),
        # by symmetry of the noncentral t: ci(-t) = -rev(ci(t))
        (-12.0, 20, -3.62846102590, -1.72241777221),
    ],
)
def test_dz_interval_where_a_fixed_bracket_met_nan(
    t: float, n: int, low: float, high: float
) -> None:
    """scipy's nct.cdf(-3.71, 19, 6.29) is NaN: the old bracket t +/- 10 gave n/a."""
    got = dz_interval(t, n)
    assert got == pytest.approx((low, high), rel=1e-9)


def test_all_zero_differences_are_not_testable_and_leave_the_family_saying_so() -> None:
    long = []
    for group, shift in (("novice", 0.0), ("expert", -5.0), ("outsider", -5.0)):
        for i in range(4):
            for condition, value in (("VO", 50.0 + 5 * i), ("HV", 50.0 + 5 * i + shift)):
                long.append((f"{group}{i}", group, "lcca", condition, "tlx_raw", value))
    rows, _ = comparison_rows(long)
    by = {r["group"]: r for r in rows}
    assert by["novice"]["test"] == "none"
    assert by["novice"]["not_testable"] == "every difference is 0"
    assert np.isnan(by["novice"]["p"])
    assert np.isnan(by["novice"]["p_holm"])
    assert by["novice"]["holm_family"] == "not a member (of expert, outsider)"
    # two members at p = 2 / 2^4 = .125 each: Holm 0.25 for both
    assert by["expert"]["p_holm"] == pytest.approx(0.25)
    assert by["expert"]["holm_family"] == "expert, outsider"


def test_success_takes_the_exact_mcnemar_test() -> None:
    # binom.test(1, 7)$p.value -> 0.125: 6 succeed in HV only, 1 in VO only
    trials = []
    outcomes = [(False, True)] * 6 + [(True, False)] + [(True, True)] * 3
    for i, (vo, hv) in enumerate(outcomes):
        for condition, ok in (("VO", vo), ("HV", hv)):
            trials.append(
                {"participant": f"P{i:02d}", "group": "novice", "task": "lcca"}
                | {"condition": condition, "success": ok}
            )
    [row], excluded = success_rows(trials)
    assert (row["vo_only"], row["hv_only"], row["n"]) == (1, 6, 10)
    assert row["p"] == pytest.approx(0.125, rel=1e-12)
    assert excluded == []


def test_equivalence_bounds_are_stated_as_a_paper_writes_them() -> None:
    from study.analysis.paired import EquivalenceBounds

    bounds = EquivalenceBounds(fraction=0.1, absolute={"peak_distal_force_n": 0.05})
    assert bounds.describe() == (
        "peak_distal_force_n ±0.05; ±10 % of the VO mean for the other measures"
    )
    assert bounds.bound("completion_time_s", -30.0) == 3.0  # a tenth of |mean|, by hand
    assert EquivalenceBounds().describe() == ""
