"""Error metrics of the paper's tables: RMSE, MAE, MaxAE, the tracking score (eq. 11), lag."""

from __future__ import annotations

import numpy as np

from teleop_core._typing import Float1D


def rmse(estimate: Float1D, truth: Float1D) -> float:
    return float(np.sqrt(np.mean((np.asarray(estimate) - np.asarray(truth)) ** 2)))


def mae(estimate: Float1D, truth: Float1D) -> float:
    return float(np.mean(np.abs(np.asarray(estimate) - np.asarray(truth))))


def max_abs_error(estimate: Float1D, truth: Float1D) -> float:
    return float(np.max(np.abs(np.asarray(estimate) - np.asarray(truth))))


def tracking_score(measured: Float1D, expected: Float1D) -> float:
    """Eq. 11: (1 - RMSE / (max(expected) - min(expected))) x 100, in %."""
    expected = np.asarray(expected)
    span = float(expected.max() - expected.min())
    return (1.0 - rmse(measured, expected) / span) * 100.0


def error_summary(estimate: Float1D, truth: Float1D) -> dict[str, float]:
    """RMSE, MAE, MaxAE, mean error and its standard deviation (N or the inputs' unit)."""
    err = np.asarray(estimate) - np.asarray(truth)
    return {
        "rmse": rmse(estimate, truth),
        "mae": mae(estimate, truth),
        "max_abs_error": max_abs_error(estimate, truth),
        "mean_error": float(err.mean()),
        "std_error": float(err.std()),
    }


def lag_samples(signal: Float1D, reference: Float1D, max_lag: int = 25) -> float:
    """How many samples `signal` trails `reference`, to a fiftieth of a sample.

    The delay d minimising the mean squared difference between signal[k] and the
    reference linearly interpolated at k - d (mean levels removed): whole samples first,
    then a fine search around the best one. Positive d: `signal` comes later.
    """
    a = np.asarray(signal, float) - np.mean(signal)
    b = np.asarray(reference, float) - np.mean(reference)
    n = len(a)
    k = np.arange(max_lag + 1, n - max_lag - 1)
    grid = np.arange(n, dtype=float)

    def misfit(d: float) -> float:
        return float(np.mean((a[k] - np.interp(k - d, grid, b)) ** 2))

    whole = min(range(-max_lag, max_lag + 1), key=misfit)
    fine = np.arange(whole - 1.0, whole + 1.0 + 1e-9, 0.02)
    return float(min(fine, key=misfit))
