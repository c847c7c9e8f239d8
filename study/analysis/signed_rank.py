"""The Wilcoxon signed-rank test with the exact conditional p of tied and zero ranks.

Own code, because no kept library gives this p: scipy.stats.wilcoxon's exact
distribution assumes distinct, non-zero ranks (with ties or zeros it falls back to the
normal approximation), and `scipy.stats.permutation_test` enumerates all 2^n sign
patterns (2^49 at 49 pairs). What a reviewer of a small study expects is the
permutation distribution of the observed ranks, ties and zeros included, as R's
`coin::wilcoxsign_test(distribution = "exact")` computes it (Pratt's treatment of zeros,
coin's default: zeros are ranked with the other differences and carry no sign). That
distribution is counted here by the sums of the subsets of the (doubled, so integer)
ranks: a few thousand additions at 49 pairs. From `EXACT_MAX_N` pairs on, p is the
normal approximation of the same conditional distribution (mean sum(r) / 2, variance
sum(r^2) / 4, no continuity correction: coin's `distribution = "asymptotic"`).

The ranks are scipy.stats.rankdata's average ranks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

EXACT_MAX_N = 50
"""The signed-rank p is exact below this many pairs."""


@dataclass(frozen=True)
class SignedRank:
    """The result of `signed_rank`."""

    v: float
    """The sum of the ranks of the positive differences (Pratt ranks: zeros ranked)."""
    p: float
    """The two-sided p: P(|V - E V| >= |v - E V|) under random signs of the ranks."""
    method: str
    """``"exact"`` (the counted conditional distribution) or ``"asymptotic"``."""
    n_zero: int
    """Differences equal to zero (ranked, no sign)."""


def signed_rank(diff: np.ndarray) -> SignedRank:
    """Two-sided Wilcoxon signed-rank test of paired differences (Pratt's zeros).

    Parameters
    ----------
    diff : numpy.ndarray
        The paired differences (HV - VO), already at the data's resolution
        (`paired.at_resolution`), so that ties and zeros are the data's.

    Returns
    -------
    SignedRank
        V, p, the method and the number of zero differences; p is 1 when every
        difference is zero (no sign to test).

    Examples
    --------
    Every one of five differences negative, two ties (coin: p = 0.0625):

    >>> signed_rank(np.array([-5.0, -5.0, -10.0, -10.0, -5.0])).p
    0.0625
    """
    # lazy: scipy.stats costs 0.7 s at start-up
    from scipy.stats import rankdata

    d = np.asarray(diff, dtype=float)
    ranks = rankdata(np.abs(d))
    signed = ranks[d != 0]
    positive = d[d != 0] > 0
    v = float(signed[positive].sum())
    n_zero = int((d == 0).sum())
    if not signed.size:
        return SignedRank(v, 1.0, "exact", n_zero)
    if d.size < EXACT_MAX_N:
        return SignedRank(v, _exact_p(signed, v), "exact", n_zero)
    return SignedRank(v, _normal_p(signed, v), "asymptotic", n_zero)


def _exact_p(ranks: np.ndarray, v: float) -> float:
    """P(|V - E V| >= |v - E V|) with V the sum of a random subset of `ranks`."""
    doubled = np.rint(2 * ranks).astype(int)  # average ranks are multiples of 1/2
    total = int(doubled.sum())
    counts = np.zeros(total + 1)  # below 2^50 for fewer than 50 ranks: exact in a double
    counts[0] = 1.0
    for r in doubled:
        counts[r:] = counts[r:] + counts[: total + 1 - r]
    # s = 2V in half ranks, E s = total / 2: |2 s - total| >= |4 v - total|, in integers
    distance = abs(round(4 * v) - total)
    sums = np.arange(total + 1)
    extreme = np.abs(2 * sums - total) >= distance
    return float(min(counts[extreme].sum() / 2.0 ** len(doubled), 1.0))


def _normal_p(ranks: np.ndarray, v: float) -> float:
    """The normal approximation of the conditional distribution, no continuity correction."""
    # lazy: scipy.stats costs 0.7 s at start-up
    from scipy.stats import norm

    mean = ranks.sum() / 2.0
    sd = math.sqrt(float((ranks**2).sum()) / 4.0)
    return float(2.0 * norm.sf(abs(v - mean) / sd))
