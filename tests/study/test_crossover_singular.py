"""The crossover's within-participant checks at a singular fit: tested against the
within-participant residual, as the classical two-period crossover analysis does.

Reference, by hand: with one trial a block, each participant's second-minus-first
difference d_i carries every within-participant term. The model value ~ condition *
group + period + (1 | participant) gives d_i = period + s_i (HV - VO in group g_i),
s_i = +1 when HV came second, -1 when first. So the period's estimate, its SE and its
df are those of the intercept of the least-squares regression of d on s x group
indicators (numpy's lstsq below), df = participants - 1 - groups: the paired t test the
crossover literature runs. The REML fit of such a study is singular (the
participants' spread is drawn at zero here and its estimate comes out zero), where the
pooled residual would give too small an SE.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from study.analysis.crossover import _Cell, _fit, design_checks, with_periods


def _study(seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    rows = []
    for group, n in (("outsider", 10), ("novice", 6), ("expert", 6)):
        for i in range(n):
            order = ("VO", "HV") if i % 2 == 0 else ("HV", "VO")
            for block, condition in enumerate(order, start=1):
                rows.append(
                    {
                        "participant": f"{group[0]}{i:02d}",
                        "group": group,
                        "task": "lcca",
                        "condition": condition,
                        "block": block,
                        "trial": 1,
                        # no participant effect at all: the fit is singular
                        "m": float(1.0 + rng.normal(0.0, 0.2)),
                    }
                )
    return rows


def _singular_seed() -> int:
    for seed in range(50):
        rows = with_periods(_study(seed))
        cell = _Cell.of(rows, "m")
        fit, _ = _fit(cell, ["period"])
        if fit.theta == 0.0:
            return seed
    raise AssertionError("no singular fit in 50 seeds")


def _by_hand(rows: list[dict]) -> tuple[float, float, int]:
    people: dict[str, dict] = {}
    for r in rows:
        people.setdefault(r["participant"], {"group": r["group"]})[r["block"]] = r
    groups = sorted({p["group"] for p in people.values()})
    d, X = [], []
    for p in people.values():
        first, second = p[1], p[2]
        s = 1.0 if second["condition"] == "HV" else -1.0
        d.append(second["m"] - first["m"])
        X.append([1.0, *[s * (p["group"] == g) for g in groups]])
    X_, d_ = np.array(X), np.array(d)
    beta, *_ = np.linalg.lstsq(X_, d_, rcond=None)
    df = len(d_) - X_.shape[1]
    sigma2 = float(((d_ - X_ @ beta) ** 2).sum() / df)
    se = float(np.sqrt(sigma2 * np.linalg.inv(X_.T @ X_)[0, 0]))
    return float(beta[0]), se, df


def test_a_singular_fit_tests_the_period_within_participants() -> None:
    rows = _study(_singular_seed())
    estimate, se, df = _by_hand(rows)
    check = next(c for c in design_checks(rows, measures=("m",)).checks if c["effect"] == "period")
    assert check["estimate"] == pytest.approx(estimate, rel=1e-10)
    p = 2 * stats.t.sf(abs(estimate / se), df)
    assert check["p"] == pytest.approx(p, rel=1e-8)
    half = stats.t.ppf(0.975, df) * se
    assert check["ci"] == pytest.approx([estimate - half, estimate + half], rel=1e-8)
