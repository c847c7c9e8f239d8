"""The paper's error metrics against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from teleop_core.estimation.metrics import error_summary, lag_samples, tracking_score


def test_tracking_score_is_eq_11() -> None:
    expected = np.array([0.0, 5.0, 10.0, 10.0])
    measured = np.array([0.0, 4.0, 10.0, 11.0])
    # errors 0, -1, 0, 1: RMSE = sqrt(2/4); span = 10; score = (1 - 0.70711/10) * 100
    assert tracking_score(measured, expected) == pytest.approx((1 - np.sqrt(0.5) / 10) * 100)


def test_error_summary_by_hand() -> None:
    s = error_summary(np.array([1.0, 2.0, 4.0]), np.array([1.0, 1.0, 1.0]))
    assert s["rmse"] == pytest.approx(np.sqrt((0 + 1 + 9) / 3))
    assert s["mae"] == pytest.approx(4 / 3)
    assert s["max_abs_error"] == 3.0
    assert s["mean_error"] == pytest.approx(4 / 3)


@pytest.mark.parametrize("shift", [0, 1, 2, 3.5])
def test_lag_of_a_delayed_smooth_signal(shift: float) -> None:
    t = np.arange(2000) * 0.01
    reference = np.sin(2 * np.pi * 0.7 * t) + 0.5 * np.sin(2 * np.pi * 0.23 * t)
    delayed = np.sin(2 * np.pi * 0.7 * (t - shift * 0.01)) + 0.5 * np.sin(
        2 * np.pi * 0.23 * (t - shift * 0.01)
    )
    assert lag_samples(delayed, reference) == pytest.approx(shift, abs=0.1)
