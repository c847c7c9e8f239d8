"""One group's paired VO-HV comparison, at the data's resolution.

`paired_comparison(vo, hv, bound)` is the whole comparison of one group on its
participant means: which test, its statistic and p, the mean difference with its 95 %
confidence interval, Cohen's d_z with its interval, Hedges' g_av, the equivalence test
(TOST) and the JZS Bayes factor. The decisions are taken on the differences at the
data's resolution (`at_resolution`): rounding noise (1.2 s computed as
1.1999999999999957) must not decide which test a group gets, whether a difference is
zero, or whether two are tied.

- Every difference zero: not testable (no test, no p, no member of the Holm family).
- Every difference the same d (not zero): no t statistic exists (the SD is zero), so the
  exact signed-rank test (`signed_rank`; with every sign alike p = 2 / 2^n).
- Otherwise Shapiro-Wilk (scipy.stats.shapiro) on the differences chooses the paired
  t-test (scipy.stats.ttest_rel) or the signed-rank test.

The distributions and tests are scipy.stats'; the Bayes factor is pingouin's
`bayesfactor_ttest` (Rouder et al. 2009, r = sqrt(2) / 2, R's `BayesFactor::ttestBF`).
The interval of d_z inverts the noncentral t distribution (scipy.stats.nct with
scipy.optimize.brentq), as R's `MBESS::ci.smd` and `effectsize::cohens_d` do.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from study.analysis.signed_rank import signed_rank

ALPHA = 0.05
RESOLUTION_DIGITS = 9
"""Differences that agree to this many significant digits of the data's magnitude are
equal (and a difference that small is zero)."""
RESOLUTION_REL = 10.0**-RESOLUTION_DIGITS
JZS_SCALE = math.sqrt(2) / 2
"""The Cauchy prior's scale of the Bayes factor (BayesFactor's "medium")."""
Row = dict[str, Any]


@dataclass(frozen=True)
class EquivalenceBounds:
    """The design's equivalence bounds (`[analysis]`) for the TOST of each measure.

    A measure listed in `absolute` is tested against +/- that bound in its unit; any
    other measure against +/- `fraction` of its VO mean (when `fraction` is set).
    """

    fraction: float | None = None
    """Bound as a fraction of the group's VO mean; None: only the `absolute` ones."""
    absolute: Mapping[str, float] = field(default_factory=dict)
    """Measure name -> bound in the measure's unit."""

    def bound(self, measure: str, mean_vo: float) -> float | None:
        """The bound of `measure` for a group whose VO mean is `mean_vo` (None: no TOST)."""
        if measure in self.absolute:
            return float(self.absolute[measure])
        if self.fraction is None or not math.isfinite(mean_vo):
            return None
        return abs(mean_vo) * self.fraction

    def describe(self) -> str:
        """The bounds as methods.md states them ('' when there are none)."""
        parts = [f"{m} ±{b:g}" for m, b in self.absolute.items()]
        if self.fraction is not None:
            share = f"{self.fraction * 100:g} %"
            parts.append(f"±{share} of the VO mean for the other measures")
        return "; ".join(parts)

    @property
    def empty(self) -> bool:
        return self.fraction is None and not self.absolute


def at_resolution(diff: np.ndarray, scale: float | None = None) -> np.ndarray:
    """`diff` with rounding noise removed.

    Values within `RESOLUTION_REL` x `scale` of zero become 0, and runs of |values| that
    close become one value (the run's first), so that ties and zeros are those of the
    data's resolution.

    Parameters
    ----------
    diff : numpy.ndarray
        Differences of paired values, in the measure's unit.
    scale : float or None, optional
        The magnitude of the data the differences came from, in the same unit;
        None: the largest |diff|.

    Returns
    -------
    numpy.ndarray
        A new float array of `diff`'s shape, signs kept.

    Examples
    --------
    >>> d = at_resolution(np.array([1.1999999999999993, -1.1999999999999957, 1e-15]), 30.0)
    >>> bool(d[0] == -d[1]), float(d[2])
    (True, 0.0)
    """
    d = np.asarray(diff, dtype=float)
    if not d.size:
        return d.copy()
    size = np.abs(d)
    tol = RESOLUTION_REL * (float(size.max()) if scale is None else float(scale))
    order = np.argsort(size, kind="stable")
    snapped = size[order].copy()
    anchor = 0.0  # the run's value; zero first, so that tiny differences are zeros
    for i, v in enumerate(snapped):
        if v - anchor > tol:
            anchor = v
        snapped[i] = anchor
    out = np.empty_like(d)
    out[order] = snapped
    return np.sign(d) * out


def magnitude(vo: np.ndarray, hv: np.ndarray) -> float:
    """The largest |value| of either condition: the scale of `at_resolution`."""
    return float(max(np.abs(vo).max(initial=0.0), np.abs(hv).max(initial=0.0)))


def hedges_g_av(vo: np.ndarray, hv: np.ndarray) -> float:
    """Hedges' g_av of paired samples [lakens2013].

    Parameters
    ----------
    vo, hv : numpy.ndarray
        The participants' values in the two conditions, paired by position.

    Returns
    -------
    float
        d_av = (mean HV - mean VO) / ((SD_VO + SD_HV) / 2) (Lakens' eq. 10) times
        Hedges' correction J = 1 - 3 / (4 df - 1) with the paired design's df = n - 1;
        NaN when neither condition has any spread.
    """
    n = len(vo)
    sd_av = (np.std(vo, ddof=1) + np.std(hv, ddof=1)) / 2
    if sd_av == 0 or n < 3:
        return float("nan")  # no spread: no standardised effect
    d_av = (np.mean(hv) - np.mean(vo)) / sd_av
    return float(d_av * (1 - 3 / (4 * (n - 1) - 1)))


def rank_biserial(d: np.ndarray) -> float:
    """Matched-pairs rank-biserial correlation [kerby2014] of differences at the data's
    resolution: (R+ - R-) / (R+ + R-) over the ranks of |d| (zeros ranked, no sign, as
    the signed-rank test ranks them); 0 when every difference is zero."""
    # lazy: scipy.stats costs 0.7 s at start-up
    from scipy.stats import rankdata

    ranks = rankdata(np.abs(d))
    plus, minus = ranks[d > 0].sum(), ranks[d < 0].sum()
    return float((plus - minus) / (plus + minus)) if plus + minus else 0.0


def dz_interval(t: float, n: int, level: float = 0.95) -> tuple[float, float]:
    """The confidence interval of Cohen's d_z = t / sqrt(n), by inverting the noncentral
    t distribution of t with n - 1 df in its noncentrality (the pivot of `MBESS::ci.smd`).

    Each limit is the root of cdf(t; df, ncp) = q (scipy.optimize.brentq) in a bracket
    that starts at ncp = t and widens, doubling, until it straddles the root. A fixed
    bracket of t +/- 10 failed for t(19) = -3.71: scipy's nct gives NaN far in a tail
    (there cdf(-3.71; 19, 6.29)), and brentq cannot start from NaN.

    Parameters
    ----------
    t : float
        The paired t statistic.
    n : int
        The number of pairs (df = n - 1).
    level : float, optional
        The confidence level.

    Returns
    -------
    tuple of (float, float)
        The lower and upper limit of d_z; NaN where t is not finite.
    """
    if not math.isfinite(t) or n < 2:
        return float("nan"), float("nan")
    root_n = math.sqrt(n)
    tail = (1 - level) / 2
    return _ncp_root(t, n - 1, 1 - tail) / root_n, _ncp_root(t, n - 1, tail) / root_n


def _nct_cdf(t: float, df: int, ncp: float) -> float:
    """cdf(t; df, ncp) of the noncentral t, falling from 1 to 0 as ncp grows; where
    scipy's value is NaN (far in a tail) the limit on that side.

    `scipy.special.nctdtr` is the function `scipy.stats.nct.cdf` evaluates (its `_cdf`),
    called directly: the root search calls it about thirty times per limit, and the
    distribution object's argument handling took most of each call."""
    # lazy: scipy.special costs 0.1 s at start-up
    from scipy.special import nctdtr

    p = float(nctdtr(df, ncp, t))
    if math.isfinite(p):
        return p
    return 0.0 if ncp > t else 1.0


def _ncp_root(t: float, df: int, q: float) -> float:
    """The noncentrality whose distribution has `t` at its `q` quantile."""
    # lazy: scipy.optimize costs 0.3 s at start-up
    from scipy.optimize import brentq

    def f(ncp: float) -> float:
        return _nct_cdf(t, df, ncp) - q

    # the cdf falls with ncp: the root lies above t where f(t) > 0, else below
    direction = 1.0 if f(t) > 0 else -1.0
    near, step = t, 1.0
    for _ in range(64):
        far = t + direction * step
        if (f(far) > 0) != (f(near) > 0):
            lo, hi = sorted((near, far))
            return float(brentq(f, lo, hi, xtol=1e-12, rtol=1e-14))
        near, step = far, step * 2
    return float("nan")


def _constant_row(d: np.ndarray) -> Row:
    """Every difference the same: no t, no Shapiro-Wilk; the exact signed-rank test, or
    not testable when that difference is zero."""
    value = float(d[0])
    if value == 0:
        return {"test": "none", "not_testable": "every difference is 0", "constant_diff": 0.0}
    result = signed_rank(d)
    return {
        "test": "wilcoxon",
        "statistic": result.v,
        "p": result.p,
        "p_method": result.method,
        "effect_size": rank_biserial(d),
        "effect_size_kind": "rank_biserial",
        "constant_diff": value,
    }


def _t_parts(vo: np.ndarray, hv: np.ndarray, bound: float | None) -> Row:
    """The t-based numbers of differences with a spread: t, its df and p, the mean
    difference's interval, d_z with its interval, TOST and BF10."""
    # lazy: scipy costs 0.7 s at start-up
    from scipy import stats

    n = len(vo)
    test = stats.ttest_rel(hv, vo)
    ci = test.confidence_interval(0.95)
    t = float(test.statistic)
    low, high = dz_interval(t, n)
    row: Row = {
        "t": t,
        "df": n - 1,
        "p_t": float(test.pvalue),
        "diff_ci_low": float(ci.low),
        "diff_ci_high": float(ci.high),
        "dz": t / math.sqrt(n),
        "dz_ci_low": low,
        "dz_ci_high": high,
        "bf10": _bf10(t, n),
        "g_av": hedges_g_av(vo, hv),
    }
    if bound is not None and bound > 0:
        # TOST (Schuirmann 1987): both one-sided tests against -bound and +bound
        lower = stats.ttest_rel(hv, vo - bound, alternative="greater").pvalue
        upper = stats.ttest_rel(hv, vo + bound, alternative="less").pvalue
        row.update(tost_bound=float(bound), tost_p=float(max(lower, upper)))
    return row


def _bf10(t: float, n: int) -> float:
    # lazy: pingouin costs 1.4 s at start-up
    import pingouin

    return float(pingouin.bayesfactor_ttest(t, n, paired=True, r=JZS_SCALE))


def paired_p(vo: np.ndarray, hv: np.ndarray) -> float:
    """The two-sided p of the test `paired_comparison` picks, alone (`study power`
    runs it on thousands of simulated groups); NaN when not testable."""
    # lazy: scipy.stats costs 0.7 s at start-up
    from scipy.stats import shapiro, ttest_rel

    vo, hv = np.asarray(vo, dtype=float), np.asarray(hv, dtype=float)
    d = at_resolution(hv - vo, magnitude(vo, hv))
    if np.all(d == d[0]):
        return float("nan") if d[0] == 0 else signed_rank(d).p
    if shapiro(d).pvalue >= ALPHA:
        return float(ttest_rel(hv, vo).pvalue)
    return signed_rank(d).p


def paired_comparison(vo: np.ndarray, hv: np.ndarray, bound: float | None = None) -> Row:
    """HV against VO in one group: the test the differences call for and its numbers.

    Parameters
    ----------
    vo, hv : numpy.ndarray
        The participants' means in the two conditions, paired by position (n >= 3).
    bound : float or None, optional
        The TOST equivalence bound in the measure's unit (None: no TOST).

    Returns
    -------
    dict of str to Any
        mean_vo, mean_hv, sd_vo, sd_hv, mean_diff; test (``paired_t``, ``wilcoxon`` or
        ``none``), statistic (t or V), p, p_method, df (t-tests), shapiro_p,
        effect_size and effect_size_kind (Hedges' g_av or the rank-biserial r), dz,
        dz_ci_low, dz_ci_high, diff_ci_low, diff_ci_high, tost_bound, tost_p, bf10,
        constant_diff (the one difference when every difference is the same, else NaN)
        and not_testable (the reason, or '').
    """
    vo, hv = np.asarray(vo, dtype=float), np.asarray(hv, dtype=float)
    d = at_resolution(hv - vo, magnitude(vo, hv))
    row: Row = {
        "mean_vo": float(vo.mean()),
        "mean_hv": float(hv.mean()),
        "sd_vo": float(vo.std(ddof=1)),
        "sd_hv": float(hv.std(ddof=1)),
        "mean_diff": float((hv - vo).mean()),
        "not_testable": "",
    }
    if np.all(d == d[0]):
        row["mean_diff"] = float(d[0])
        row.update(_constant_row(d))
        return row
    # lazy: scipy.stats costs 0.7 s at start-up
    from scipy.stats import shapiro

    row["shapiro_p"] = float(shapiro(d).pvalue)
    row.update(_t_parts(vo, hv, bound))
    if row["shapiro_p"] >= ALPHA:
        row.update(
            test="paired_t",
            statistic=row["t"],
            p=row["p_t"],
            p_method="t distribution",
            effect_size=hedges_g_av(vo, hv),
            effect_size_kind="hedges_g_av",
        )
    else:
        result = signed_rank(d)
        row.update(
            test="wilcoxon",
            statistic=result.v,
            p=result.p,
            p_method=result.method,
            effect_size=rank_biserial(d),
            effect_size_kind="rank_biserial",
        )
    return row
