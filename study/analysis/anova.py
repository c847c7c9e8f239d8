"""The mixed ANOVA's arithmetic (`stats.mixed_anova`): with two conditions it is two
one-way between-subject models, each fitted by statsmodels' OLS and tested by its
nested-model F test (`OLSResults.compare_f_test`).

The split is the multivariate approach car::Anova and afex use for a within factor of two
levels: the participant sums s = (a + b) / sqrt 2 carry the group effect; the
differences d = (b - a) / sqrt 2 carry the condition effect (the mean of d) and the
interaction (the group term of d ~ group). The design matrices are built here from the
group labels (sum-to-zero contrasts) rather than through a formula: the models are fixed,
and statsmodels' formula layer would parse six formulas per measure to build the same
columns. Not `pingouin.mixed_anova`: it gives Type II only, and `study analyze --ss-type 3`
(afex's default) needs Type III. The values equal R's afex `aov_ez(type = 2|3)`
(tests/study/test_analysis.py quotes them).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from study.analysis.paired import RESOLUTION_REL, magnitude


def _sum_coded(group: np.ndarray) -> np.ndarray:
    """The group's sum-to-zero contrast columns (R's `contr.sum`: the last level -1)."""
    labels, index = np.unique(group, return_inverse=True)
    k = len(labels)
    coding = np.vstack([np.eye(k - 1), -np.ones(k - 1)]) if k > 1 else np.zeros((1, 0))
    return coding[index]


def _f_test(
    y: np.ndarray, full: np.ndarray, restricted: np.ndarray, zero_ss: float
) -> dict[str, float]:
    """statsmodels' F test of the OLS model `full` against the nested `restricted`.

    The effect's sum of squares is the restricted model's residual SS minus the full
    one's. A residual SS at most `zero_ss` (the data's resolution: every participant of a
    group alike, up to rounding) is an exact fit with no error to test against: no F, no
    p (`exact_fit` True), where the ratio of rounding errors would give F ~ 1e30.
    """
    from statsmodels.regression.linear_model import OLS

    fit = OLS(y, full).fit()
    reduced = OLS(y, restricted).fit() if restricted.shape[1] else None
    ssr_restricted = reduced.ssr if reduced is not None else float(y @ y)
    df_effect = full.shape[1] - restricted.shape[1]
    effect = max(ssr_restricted - fit.ssr, 0.0)
    if fit.ssr <= zero_ss:
        f = p = np2 = math.nan
    elif reduced is not None:
        f, p, _ = fit.compare_f_test(reduced)
        np2 = effect / (effect + fit.ssr)
    else:  # no column left: the restricted model predicts 0
        from scipy.stats import f as f_dist

        f = effect / df_effect / (fit.ssr / fit.df_resid)
        p = f_dist.sf(f, df_effect, fit.df_resid)
        np2 = effect / (effect + fit.ssr)
    return {
        "F": float(f),
        "df1": float(df_effect),
        "df2": float(fit.df_resid),
        "p": float(p),
        "np2": float(np2),
        "exact_fit": bool(fit.ssr <= zero_ss),
    }


def anova_rows(
    group: np.ndarray, a: np.ndarray, b: np.ndarray, ss_type: int
) -> list[dict[str, Any]]:
    """Group (between) x condition (two levels, within), one participant per element:
    their group and their means in the two conditions `a` and `b`.

    Group: s ~ 1 + group against s ~ 1. Interaction: d ~ 1 + group against d ~ 1.
    Condition, Type III: d ~ 1 + group (sum-coded) against the same without the intercept
    (the unweighted mean of the group means is 0); Type II: against the group columns
    centred on their participant-weighted means, no intercept (the participants' mean
    difference is 0; its SS is N mean(d)^2). A term whose model fits exactly has
    `exact_fit` True and no F or p.
    """
    y_between = (a + b) / math.sqrt(2)
    y_within = (b - a) / math.sqrt(2)
    codes = _sum_coded(np.asarray(group))
    ones = np.ones((len(y_within), 1))
    full = np.column_stack([ones, codes])
    condition_restricted = codes if ss_type == 3 else codes - codes.mean(axis=0)
    tests = (
        ("group", y_between, ones),
        ("condition", y_within, condition_restricted),
        ("interaction", y_within, ones),
    )
    # the data's resolution (as the paired comparisons'): 9 significant digits of the
    # values' magnitude, per participant
    zero_ss = len(a) * (RESOLUTION_REL * magnitude(a, b)) ** 2
    return [
        {"source": source, **_f_test(y, full, restricted, zero_ss), "ss_type": ss_type}
        for source, y, restricted in tests
    ]
