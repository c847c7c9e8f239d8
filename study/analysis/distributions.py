"""The distribution functions and rank statistics of the analysis, in the standard library
and numpy: `study analyze` loads no scipy.

scipy.stats cost `study analyze` more CPU time than the whole statistics (its import
alone parses the docstrings of a hundred distributions), and scipy.special or
scipy.optimize alone still cost about as much as numpy. What the analysis needs is
small: the normal distribution (`math.erfc`; `statistics.NormalDist.inv_cdf`, Wichura's
AS241, the algorithm of R's `qnorm`), Student's t and the F distribution through the
regularized incomplete beta function (its continued fraction, Numerical Recipes 6.4, in
the tail it is asked for, so small p-values keep their digits), the Shapiro-Wilk test
(Royston's AS R94, line for line R's `swilk.c`), the exact and the normal-approximation
p of the Wilcoxon signed-rank test (R's `wilcox.test`), average ranks, and Brent's root
finder (scipy's `brentq`, line for line). tests/study/test_distributions.py checks each
against scipy and R.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from statistics import NormalDist

import numpy as np

_NORMAL = NormalDist()
_EPS = 2.220446049250313e-16
_TINY = 1e-300


def norm_sf(x: float) -> float:
    """P(Z > x) for a standard normal Z, with full relative precision in the upper tail."""
    return 0.5 * math.erfc(x / math.sqrt(2.0))


def norm_ppf(q: float) -> float:
    """The standard normal quantile (AS241, as R's `qnorm`)."""
    return _NORMAL.inv_cdf(q)


def _beta_fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of I_x(a, b) (modified Lentz), converging for x < (a+1)/(a+b+2)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > _TINY else _TINY)
    h = d
    for m in range(1, 10_000):
        m2 = 2 * m
        for aa in (
            m * (b - m) * x / ((qam + m2) * (a + m2)),
            -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)),
        ):
            d = 1.0 + aa * d
            d = 1.0 / (d if abs(d) > _TINY else _TINY)
            c = 1.0 + aa / c
            c = c if abs(c) > _TINY else _TINY
            step = d * c
            h *= step
        if abs(step - 1.0) < _EPS:
            return h
    raise ArithmeticError(f"incomplete beta ({a}, {b}, {x}) did not converge")  # pragma: no cover


def beta_lower(a: float, b: float, x: float, y: float) -> float:
    """The regularized incomplete beta function I_x(a, b), with y = 1 - x given exactly
    (so that a tail near x = 1 keeps its digits)."""
    if x <= 0.0:
        return 0.0
    if y <= 0.0:
        return 1.0
    log_front = (
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log(y)
    )
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _beta_fraction(a, b, x) / a
    return 1.0 - math.exp(log_front) * _beta_fraction(b, a, y) / b


def beta_upper(a: float, b: float, x: float, y: float) -> float:
    """1 - I_x(a, b) = I_y(b, a), computed in whichever tail is small."""
    return beta_lower(b, a, y, x)


def t_sf(t: float, df: float) -> float:
    """P(T > t) for Student's t with `df` degrees of freedom."""
    if math.isnan(t):
        return math.nan
    if math.isinf(t):
        return 0.0 if t > 0 else 1.0
    t2 = t * t
    both_tails = beta_lower(df / 2.0, 0.5, df / (df + t2), t2 / (df + t2))  # P(|T| > |t|)
    return both_tails / 2.0 if t > 0 else 1.0 - both_tails / 2.0


def t_two_sided(t: float, df: float) -> float:
    """P(|T| >= |t|): the two-sided p of a t statistic."""
    if math.isnan(t):
        return math.nan
    if math.isinf(t):
        return 0.0
    t2 = t * t
    return beta_lower(df / 2.0, 0.5, df / (df + t2), t2 / (df + t2))


def t_ppf(q: float, df: float) -> float:
    """The q quantile of Student's t (the root of t_sf(t) = 1 - q, to machine precision)."""
    if not 0.0 < q < 1.0:
        return {0.0: -math.inf, 1.0: math.inf}.get(q, math.nan)
    if q < 0.5:
        return -t_ppf(1.0 - q, df)
    if q == 0.5:
        return 0.0
    tail = 1.0 - q
    hi = 1.0
    while t_sf(hi, df) > tail:
        hi *= 2.0
    return brentq(lambda t: t_sf(t, df) - tail, 0.0, hi, xtol=1e-300)


def f_sf(f: float, df1: float, df2: float) -> float:
    """P(F > f) for the F distribution with (df1, df2) degrees of freedom; inf -> 0."""
    if math.isnan(f):
        return math.nan
    if math.isinf(f):
        return 0.0
    if f <= 0.0:
        return 1.0
    x, y = df2 / (df2 + df1 * f), df1 * f / (df2 + df1 * f)
    return beta_lower(df2 / 2.0, df1 / 2.0, x, y)


def brentq(
    f: Callable[[float], float],
    xa: float,
    xb: float,
    xtol: float = 2e-12,
    rtol: float = 4 * _EPS,
    maxiter: int = 100,
) -> float:
    """A root of f in [xa, xb] (f(xa), f(xb) of opposite signs): Brent's method as scipy's
    `optimize.brentq` runs it (scipy/optimize/Zeros/brentq.c), the same iterates."""
    xpre, xcur = xa, xb
    xblk = fblk = spre = scur = 0.0
    fpre, fcur = f(xpre), f(xcur)
    if fpre * fcur > 0:
        raise ValueError("f(a) and f(b) must have different signs")
    if fpre == 0:
        return xpre
    if fcur == 0:
        return xcur
    for _ in range(maxiter):
        if fpre != 0 and fcur != 0 and (math.copysign(1, fpre) != math.copysign(1, fcur)):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:  # interpolate
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:  # extrapolate
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2 * abs(stry) < min(abs(spre), 3 * abs(sbis) - delta):  # good short step
                spre, scur = scur, stry
            else:  # bisect
                spre = scur = sbis
        else:  # bisect
            spre = scur = sbis
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0 else -delta)
        fcur = f(xcur)
    raise ArithmeticError(f"brentq did not converge in {maxiter} iterations")


def rank_average(x: np.ndarray) -> np.ndarray:
    """Ranks 1..n, ties given their average rank (scipy's `rankdata`, R's `rank`)."""
    x = np.asarray(x, dtype=float)
    if not x.size:
        return np.empty(0)
    order = np.argsort(x, kind="mergesort")
    ordered = x[order]
    new = np.r_[True, ordered[1:] != ordered[:-1]]
    starts = np.flatnonzero(np.r_[new, True])
    average = (starts[:-1] + starts[1:] + 1) / 2.0
    ranks = np.empty(x.size)
    ranks[order] = average[np.cumsum(new) - 1]
    return ranks


def signed_rank_exact_p(v: float, n: int) -> float:
    """Two-sided exact p of the signed-rank statistic V (the sum of the positive ranks of
    n distinct, non-zero differences): R's `wilcox.test(exact = TRUE)` with `psignrank`,
    the null distribution counted (subsets of 1..n by their sum)."""
    counts = np.zeros(n * (n + 1) // 2 + 1)  # below 2^49 for n < 50: exact in a double
    counts[0] = 1.0
    for k in range(1, n + 1):
        counts[k:] = counts[k:] + counts[:-k]
    total = 2.0**n
    v = round(v)
    if v > n * (n + 1) / 4:
        p = counts[v:].sum() / total  # P(V >= v)
    else:
        p = counts[: v + 1].sum() / total  # P(V <= v)
    return float(min(2.0 * p, 1.0))


def signed_rank_normal_p(ranks: np.ndarray, v: float) -> float:
    """Two-sided p of V by the normal approximation with the tie-corrected variance and a
    continuity correction (R's `wilcox.test(exact = FALSE, correct = TRUE)`); `ranks` are
    the average ranks of the non-zero |differences|."""
    n = ranks.size
    _, ties = np.unique(ranks, return_counts=True)
    z = v - n * (n + 1) / 4.0
    sigma = math.sqrt(n * (n + 1) * (2 * n + 1) / 24.0 - float((ties**3 - ties).sum()) / 48.0)
    if sigma == 0:
        return math.nan
    z = (z - math.copysign(0.5, z) * (z != 0)) / sigma
    return 2.0 * norm_sf(abs(z))


# Royston (1995), AS R94: the polynomial coefficients of R's swilk.c
_C1 = (0.0, 0.221157, -0.147981, -2.07119, 4.434685, -2.706056)
_C2 = (0.0, 0.042981, -0.293762, -1.752461, 5.682633, -3.582633)
_C3 = (0.544, -0.39978, 0.025054, -6.714e-4)
_C4 = (1.3822, -0.77857, 0.062767, -0.0020322)
_C5 = (-1.5861, -0.31082, -0.083751, 0.0038915)
_C6 = (-0.4803, -0.082676, 0.0030302)
_G = (-2.273, 0.459)


def _poly(c: tuple[float, ...], x: float) -> float:
    """swilk.c's `poly`: c[0] + c[1] x + ... + c[-1] x^(len - 1)."""
    if len(c) == 1:
        return c[0]
    p = x * c[-1]
    for coefficient in c[-2:0:-1]:
        p = (p + coefficient) * x
    return c[0] + p


def shapiro_wilk(x: np.ndarray) -> tuple[float, float]:
    """The Shapiro-Wilk test of normality: (W, p), Royston's AS R94 as R's `shapiro.test`
    computes it, for 3 to 5000 values that are not all equal."""
    x = np.sort(np.asarray(x, dtype=float))
    n = x.size
    if not 3 <= n <= 5000:
        raise ValueError(f"{n} values for the Shapiro-Wilk test; expected 3 to 5000")
    half = n // 2
    if n == 3:
        a = np.array([math.sqrt(0.5)])
    else:
        m = np.array([norm_ppf((i - 0.375) / (n + 0.25)) for i in range(1, half + 1)])
        summ2 = 2.0 * float(m @ m)
        ssumm2 = math.sqrt(summ2)
        rsn = 1.0 / math.sqrt(n)
        a1 = _poly(_C1, rsn) - m[0] / ssumm2
        if n > 5:
            a2 = -m[1] / ssumm2 + _poly(_C2, rsn)
            fac = math.sqrt((summ2 - 2 * m[0] ** 2 - 2 * m[1] ** 2) / (1 - 2 * a1**2 - 2 * a2**2))
            a = m / -fac
            a[1] = a2
        else:
            fac = math.sqrt((summ2 - 2 * m[0] ** 2) / (1 - 2 * a1**2))
            a = m / -fac
        a[0] = a1
    spread = x[-1] - x[0]
    if spread < 1e-19:
        raise ValueError("all values are identical; the Shapiro-Wilk test needs a spread")
    coefficients = np.zeros(n)
    coefficients[:half] = -a
    coefficients[n - half :] = a[::-1]
    scaled = x / spread
    asa = coefficients - coefficients.sum() / n
    xsx = scaled - scaled.sum() / n
    ssa, ssx, sax = float(asa @ asa), float(xsx @ xsx), float(asa @ xsx)
    root = math.sqrt(ssa * ssx)
    w1 = (root - sax) * (root + sax) / (ssa * ssx)  # 1 - W, without its rounding error
    w = 1.0 - w1
    if n == 3:  # exact
        return w, max(0.0, 1.90985931710274 * (math.asin(math.sqrt(w)) - 1.04719755119660))
    y, log_n = math.log(w1), math.log(n)
    if n <= 11:
        gamma = _poly(_G, n)
        if y >= gamma:
            return w, 1e-99
        y = -math.log(gamma - y)
        mean, sd = _poly(_C3, n), math.exp(_poly(_C4, n))
    else:
        mean, sd = _poly(_C5, log_n), math.exp(_poly(_C6, log_n))
    return w, norm_sf((y - mean) / sd)
