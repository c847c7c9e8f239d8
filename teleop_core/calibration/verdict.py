"""The loop's honest verdict on what it leaves: `white` or `structure_remains`, and where.

- `fit_percent`: the normalised fit of MATLAB's `compare`,
  100 (1 - ||y - y_hat|| / ||y - mean(y)||).
- `unexplained`: where the held-out residual concentrates. For every recorded channel
  and derived quantity (speed band, direction of motion, time window, angle or
  position, load, distance travelled since the last reversal) the residual is
  averaged in quantile bins of that quantity; the share of the residual's variance
  that the bin means explain (the correlation ratio eta^2 of a one-way ANOVA,
  `scipy.stats` has no binned version) says how much of it that quantity accounts
  for, beyond what the same quantity explains when circularly shifted against the
  residual (chance, with both series' autocorrelation kept). The largest is named.
- `verdict`: `structure_remains` when the held-out residual is smooth in time (the
  Durbin-Watson statistic, `statsmodels.stats.stattools.durbin_watson`, below
  `DW_STRUCTURE`) or one quantity explains more than `SHARE_STRUCTURE` of its variance
  beyond chance; `white` otherwise. Not Ljung-Box at 25 lags, which the report keeps:
  a model whose regressors are measured with noise (current, and an acceleration
  differenced from a noisy speed) leaves a residual with a short negative
  autocorrelation that no effect can remove, and over 12,000 held-out samples
  Ljung-Box refuses it on 3 clean recordings in 10, while Durbin-Watson sees it above 2.
  The binned share is also what keeps a clean recording's verdict white when the
  lagged cross-correlation flags inputs that the residual merely shares a spectrum
  with.

Written by hand because it is a few lines of numpy over `np.bincount`; pandas'
`qcut` + `groupby` gives the same bins and was 20x slower on 50,000 samples.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d
from statsmodels.stats.stattools import durbin_watson

from teleop_core._typing import Float1D
from teleop_core.calibration.library import distance_since_turn

BINS = 20
"""Quantile bins per quantity."""
SHARE_STRUCTURE = 0.02
"""Share of the held-out residual variance, beyond the largest share a circularly
shifted copy of the quantity explains by chance, that one quantity's bin means must
explain to count as structure."""
DW_STRUCTURE = 1.6
"""Durbin-Watson statistic below which the residual counts as smooth in time: lag-1
autocorrelation above 0.2, i.e. a slow part of at least a fifth of its variance."""
SMOOTH_S = 0.1
"""Width of the moving average over each binned channel, s."""
SHIFTS = 39
"""Circular shifts in the chance reference (the largest of 39: p < 0.025)."""


def fit_percent(y: Float1D, y_hat: Float1D) -> float:
    """MATLAB `compare`'s NRMSE fit, %: 100 (1 - ||y - y_hat|| / ||y - mean(y)||)."""
    y, y_hat = np.asarray(y, float), np.asarray(y_hat, float)
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / np.linalg.norm(y - y.mean())))


def distance_since_reversal(position: Float1D, speed: Float1D) -> Float1D:
    """|position - position where the speed last changed sign| (from the start until the
    first reversal). For a noise-free speed (the generators' truth); on a measured one
    `library.distance_since_turn`, from the angle's turns, is the quantity."""
    sign = np.sign(speed)
    # carry the last non-zero sign forward so that rest does not count as a reversal
    nz = np.flatnonzero(sign)
    if len(nz) == 0:
        return np.zeros_like(position)
    idx = np.maximum.accumulate(np.where(sign != 0, np.arange(len(sign)), 0))
    held = sign[idx]
    held[: nz[0]] = sign[nz[0]]
    change = np.flatnonzero(np.diff(held) != 0) + 1
    turn = np.zeros(len(position), dtype=np.int64)
    turn[change] = change - 1  # the last sample before the sign changed: the turning point
    turn = np.maximum.accumulate(turn)
    return np.abs(position - position[turn])


def _smooth(x: Float1D, width: int) -> Float1D:
    """Zero-phase moving average: a noisy channel binned as it is sorts the residual by
    its own measurement noise (errors in variables: a clean recording's residual then
    'depends' on the measured current), so channels are binned smoothed."""
    return uniform_filter1d(np.asarray(x, float), size=width, mode="nearest")


def quantities(signals: dict[str, Float1D], prediction: Float1D) -> dict[str, Float1D]:
    """The channels and derived quantities the residual is binned against (smoothed
    over `SMOOTH_S`; direction and time as they are)."""
    t = signals["t"]
    width = max(3, round(SMOOTH_S / float(np.median(np.diff(t)))) | 1)
    return {
        name: (x if name in ("direction", "time window") else _smooth(x, width))
        for name, x in _raw_quantities(signals, prediction).items()
    }


def _raw_quantities(signals: dict[str, Float1D], prediction: Float1D) -> dict[str, Float1D]:
    out: dict[str, Float1D] = {}
    for name, v in signals.items():
        if name in ("direction", "direction_sign") or np.ptp(v) == 0:
            continue
        out["time window" if name == "t" else name] = np.asarray(v, float)
    if "speed" in signals:
        speed = signals["speed"]
        out["speed band"] = np.abs(speed)
        out["direction"] = np.sign(speed)
        if "angle" in signals:
            # from the angle's turns, not the speed's sign changes: the speed sensor's
            # noise flips the sign at every slow stretch, and each flip would restart
            # the distance there
            out["distance since reversal"] = distance_since_turn(signals["angle"])
    out["load"] = np.abs(np.asarray(prediction, float))
    return out


def binned_share(residual: Float1D, x: Float1D, bins: int = BINS) -> tuple[float, list[dict]]:
    """Share of var(residual) explained by its means in quantile bins of x, and the bins.

    A quantity with at most `bins` distinct values (the direction of motion, -1/0/+1)
    is binned by value: its quantiles would merge them all into one bin.
    """
    e = np.asarray(residual, float)
    binned = _bin_index(np.asarray(x, float), bins)
    if binned is None:
        return 0.0, []
    k, lows, highs = binned
    share, count, mean = _share(e, k, len(lows))
    table = [
        {
            "low": float(lows[i]),
            "high": float(highs[i]),
            "n": int(count[i]),
            "mean_residual": float(mean[i]),
        }
        for i in range(len(count))
        if count[i]
    ]
    return share, table


def _bin_index(x: Float1D, bins: int) -> tuple[np.ndarray, Float1D, Float1D] | None:
    """Each sample's bin (by value, or by quantile of x) and the bins' low and high
    ends; None when x has a single value."""
    values = np.unique(x)
    if len(values) <= bins:
        if len(values) < 2:
            return None
        return np.searchsorted(values, x), values, values
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    k = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    return k, edges[:-1], edges[1:]


def _share(e: Float1D, k: np.ndarray, bins: int) -> tuple[float, np.ndarray, Float1D]:
    """Share of var(e) that the means of e in the bins `k` explain, the bins' counts
    and means."""
    count = np.bincount(k, minlength=bins)
    total = np.bincount(k, weights=e, minlength=bins)
    mean = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
    ss_total = float(np.sum((e - e.mean()) ** 2))
    ss_between = float(np.sum(count * (mean - e.mean()) ** 2))
    return (ss_between / ss_total if ss_total > 0 else 0.0), count, mean


def null_share(residual: Float1D, x: Float1D, shifts: int = SHIFTS, seed: int = 0) -> Float1D:
    """Shares that x explains by chance: x circularly shifted against the residual by
    `shifts` random offsets of at least a tenth of the record. A shift keeps both
    series' autocorrelation, so slow noise or a slowly varying quantity (few long
    stretches per bin) does not pass for structure, as it would against n i.i.d.
    samples.

    A shifted x has the same values, hence the same quantile bins, as x: each sample's
    bin is found once and the bin indices are shifted (`binned_share` of the shifted
    x, without sorting it again for every offset).
    """
    n = len(x)
    rng = np.random.default_rng(seed)
    offsets = rng.integers(n // 10, n - n // 10, size=shifts)
    e = np.asarray(residual, float)
    binned = _bin_index(np.asarray(x, float), BINS)
    if binned is None:
        return np.zeros(shifts)
    k, lows, _ = binned
    return np.array([_share(e, np.roll(k, int(o)), len(lows))[0] for o in offsets])


def unexplained(
    residual: Float1D, signals: dict[str, Float1D], prediction: Float1D
) -> dict[str, Any]:
    """Where the residual concentrates: the quantity whose bins explain most of it
    beyond chance (`share_of_variance` minus the largest share of `null_share`)."""
    shares: dict[str, float] = {}
    excess: dict[str, float] = {}
    tables: dict[str, list[dict]] = {}
    for name, x in quantities(signals, prediction).items():
        shares[name], tables[name] = binned_share(residual, x)
        excess[name] = shares[name] - float(np.max(null_share(residual, x)))
    best = max(excess, key=excess.__getitem__) if excess else None
    return {
        "quantity": best,
        "share_of_variance": shares.get(best, 0.0) if best else 0.0,
        "share_beyond_chance": excess.get(best, 0.0) if best else 0.0,
        "bins": tables.get(best, []) if best else [],
        "shares": dict(sorted(shares.items(), key=lambda kv: -kv[1])),
        "shares_beyond_chance": dict(sorted(excess.items(), key=lambda kv: -kv[1])),
    }


def verdict(residual: Float1D, where: dict[str, Any]) -> str:
    """`white` or `structure_remains` (see the module docstring)."""
    smooth = durbin_watson(np.asarray(residual, float)) < DW_STRUCTURE
    return (
        "structure_remains"
        if smooth or where["share_beyond_chance"] >= SHARE_STRUCTURE
        else ("white")
    )
