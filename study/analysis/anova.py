"""The mixed ANOVA's arithmetic (`stats.mixed_anova`): with two conditions it is two
one-way between-subject models, computed here in closed form.

Written by hand rather than through statsmodels' `anova_lm(OLS.from_formula(...))`:
the sums of squares of a one-way model are a few lines, and the formula parser and two
model fits per measure were most of `study analyze`'s time. The values equal R's
afex `aov_ez(type = 2|3)` (tests/study/test_analysis.py quotes them). Not
`pingouin.mixed_anova` either: it gives Type II only (equal to this one on unequal groups,
which the tests check), and `study analyze --ss-type 3` (afex's default) needs Type III,
so one closed form serves both types.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def one_way(y: np.ndarray, group: np.ndarray) -> dict[str, Any]:
    """The sums of squares of the one-way model y ~ C(group, Sum), in closed form (what
    statsmodels' `anova_lm(OLS.from_formula(...), typ=3)` gives, without a formula
    parser and two model fits per measure).

    Group: sum over groups of n_g (mean_g - mean)^2, df G - 1 (one factor: Types I-III
    agree); residual: the within-group SS, df N - G. The intercept: Type II, N mean^2
    (the participant-weighted mean); Type III with sum contrasts, the unweighted mean of
    the group means m, m^2 / (sum_g 1 / n_g / G^2), its SS over the residual variance.
    """
    labels, index = np.unique(group, return_inverse=True)
    n_g = np.bincount(index).astype(float)
    mean_g = np.bincount(index, weights=y) / n_g
    n, k = len(y), len(labels)
    unweighted = mean_g.mean()
    # numpy scalars, as statsmodels' table holds: a zero residual gives F = inf (or nan)
    # with a warning, not an exception
    f64 = np.float64
    return {
        "group": {"sum_sq": f64(n_g @ (mean_g - y.mean()) ** 2), "df": f64(k - 1)},
        "residual": {"sum_sq": f64(((y - mean_g[index]) ** 2).sum()), "df": f64(n - k)},
        "intercept_ii": f64(n * y.mean() ** 2),
        "intercept_iii": f64(unweighted**2 / ((1.0 / n_g).sum() / k**2)),
    }


def anova_rows(
    group: np.ndarray, a: np.ndarray, b: np.ndarray, ss_type: int
) -> list[dict[str, Any]]:
    """Group (between) x condition (two levels, within), one participant per element:
    their group and their means in the two conditions `a` and `b`.

    With two conditions the mixed ANOVA splits into two between-subject models (the
    multivariate approach car::Anova and afex use): the participant sums
    s = (a + b) / sqrt 2 carry the group effect; the differences d = (b - a) / sqrt 2
    carry the condition effect (the intercept of d ~ group) and the interaction (the
    group term of d ~ group), both one-way models with sum-to-zero group contrasts
    (`one_way`): Type III condition is the sum-coded intercept's SS, Type II the
    intercept's alone, N mean(d)^2.
    """
    # lazy: scipy.stats costs 0.7 s at start-up
    from scipy.stats import f as f_dist

    between = one_way((a + b) / math.sqrt(2), group)
    within = one_way((b - a) / math.sqrt(2), group)
    # Type II: SS(condition) = N dbar^2; Type III: the sum-coded intercept's SS
    ss_condition = within["intercept_ii"] if ss_type == 2 else within["intercept_iii"]
    terms = (
        ("group", between["group"], between["residual"]),
        ("condition", {"sum_sq": ss_condition, "df": 1.0}, within["residual"]),
        ("interaction", within["group"], within["residual"]),
    )
    rows = []
    for source, effect, error in terms:
        # F = (SS_effect / df_effect) / (SS_error / df_error); partial eta^2 = SS / (SS + SS_err).
        # No error variance (every participant answered alike): F is inf when the effect is
        # not zero (p = 0, as R's F on an exact fit) and undefined (nan) when it is; numpy's
        # float64 division gives exactly these, so its warnings are silenced, not its values.
        with np.errstate(divide="ignore", invalid="ignore"):
            f = (effect["sum_sq"] / effect["df"]) / (error["sum_sq"] / error["df"])
            np2 = effect["sum_sq"] / (effect["sum_sq"] + error["sum_sq"])
        rows.append(
            {
                "source": source,
                "F": float(f),
                "df1": float(effect["df"]),
                "df2": float(error["df"]),
                "p": float(f_dist.sf(float(f), float(effect["df"]), float(error["df"]))),
                "np2": float(np2),
                "ss_type": ss_type,
            }
        )
    return rows
