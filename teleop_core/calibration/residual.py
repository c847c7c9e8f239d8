"""Tests on a model's held-out residual, and the test that an extra effect really helps.

- Whiteness: the Ljung-Box Q statistic (`statsmodels.stats.diagnostic.acorr_ljungbox`)
  and the sample autocorrelation (`statsmodels.tsa.stattools.acf`) against the bounds
  +-z / sqrt(N) of white noise.
- Independence from the inputs: the cross-correlation of the residual with each input
  over lags -L..L (`statsmodels.tsa.stattools.ccf` both ways round) against the same
  bounds, as MATLAB's `resid` draws it (99 % bounds by default, so z = 2.576).
- Whether a richer model predicts the held-out block better than chance: the
  Diebold-Mariano test on the absolute-error differences, with a Newey-West (HAC)
  variance because forecast errors of neighbouring samples are correlated: what an OLS
  of the differences on a constant with `cov_type="HAC"` (statsmodels) gives, in
  closed form (`_hac_t`; the tests check it against statsmodels).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.tsa.stattools import acf, ccf

from teleop_core._typing import Float1D

Z_99 = float(stats.norm.ppf(0.995))
"""Two-sided 99 % normal quantile: the bounds MATLAB's `resid` draws by default."""


def _lagged_cross(residual: Float1D, u: Float1D, lags: int) -> Float1D:
    """Cross-correlation r(k) = corr(e[t], u[t - k]) for k = -lags..lags."""
    forward = ccf(residual, u, adjusted=False, fft=True)[: lags + 1]  # corr(e[t+k], u[t])
    backward = ccf(u, residual, adjusted=False, fft=True)[1 : lags + 1]  # corr(u[t+k], e[t])
    return np.concatenate([backward[::-1], forward])


def residual_tests(
    residual: Float1D, inputs: dict[str, Float1D], max_lag: int = 25, z: float = Z_99
) -> dict[str, Any]:
    """Whiteness and input-independence of a residual, as a JSON-ready dict.

    Parameters
    ----------
    residual : (n,) array
        Reference minus model, N.
    inputs : dict of (n,) arrays
        Model inputs (current, speed, ...) to test independence from.
    max_lag
        Largest lag, samples, for the autocorrelation, Ljung-Box and cross-correlation.
    z
        Normal quantile of the bounds (+-z / sqrt(n)).

    Returns
    -------
    dict with `ljung_box` (statistic, p_value, lags), `autocorrelation` (lags, values,
    bound, outside, white) and `cross_correlation` (per input: lags, values, bound,
    outside, independent), plus `rms_n`.
    """
    e = np.asarray(residual, float)
    n = len(e)
    lags = int(min(max_lag, n // 4))
    bound = z / np.sqrt(n)
    lb = acorr_ljungbox(e, lags=[lags], return_df=True)
    p_value = float(lb["lb_pvalue"].iloc[0])
    r = acf(e, nlags=lags, fft=True)
    outside = int(np.sum(np.abs(r[1:]) > bound))
    cross: dict[str, Any] = {}
    for name, u in inputs.items():
        if np.std(u) == 0:
            continue
        c = _lagged_cross(e, np.asarray(u, float), lags)
        cross[name] = {
            "lags": list(range(-lags, lags + 1)),
            "values": [float(v) for v in c],
            "bound": float(bound),
            "outside": int(np.sum(np.abs(c) > bound)),
            "independent": bool(np.all(np.abs(c) <= bound)),
        }
    return {
        "rms_n": float(np.sqrt(np.mean(e * e))),
        "ljung_box": {"lags": lags, "statistic": float(lb["lb_stat"].iloc[0]), "p_value": p_value},
        "autocorrelation": {
            "lags": list(range(lags + 1)),
            "values": [float(v) for v in r],
            "bound": float(bound),
            "outside": outside,
            "white": bool(p_value > 0.01 and outside <= max(1, round(0.01 * lags))),
        },
        "cross_correlation": cross,
    }


def diebold_mariano(error_a: Float1D, error_b: Float1D, max_lag: int | None = None) -> float:
    """One-sided p-value that model b's held-out errors are smaller than a's.

    d_t = |e_a,t| - |e_b,t|; the statistic is mean(d) over its Newey-West standard
    error. Absolute rather than squared errors: a missing effect shows in bursts (a
    load change, a reversal), and squaring them makes d so heavy-tailed that a 70 %
    cut in RMSE on a 15 s block came out at p = 0.02.
    """
    d = np.abs(np.asarray(error_a, float)) - np.abs(np.asarray(error_b, float))
    if np.allclose(d, 0.0):
        return 1.0
    lags = max_lag if max_lag is not None else int(np.ceil(4 * (len(d) / 100) ** (2 / 9)))
    return float(stats.norm.sf(_hac_t(d, lags)))


def _hac_t(d: Float1D, lags: int) -> float:
    """t statistic of mean(d) with the Newey-West (Bartlett) variance over `lags` lags.

    What statsmodels' `OLS(d, 1).fit(cov_type="HAC", cov_kwds={"maxlags": lags})`
    computes for the constant (no small-sample correction), in closed form: with
    u = d - mean(d), S = sum u_t^2 + 2 sum_{l=1..L} (1 - l / (L + 1)) sum u_t u_{t-l}
    and var(mean) = S / n^2, without building a regression object per call.
    """
    n = len(d)
    mean = float(np.mean(d))
    u = d - mean
    s = float(u @ u)
    for lag in range(1, min(lags, n - 1) + 1):
        s += 2.0 * (1.0 - lag / (lags + 1.0)) * float(u[lag:] @ u[:-lag])
    if s <= 0.0:
        return float(np.copysign(np.inf, mean)) if mean else 0.0
    return mean / (np.sqrt(s) / n)
