"""Effects the loop used to miss on recordings drawn as the generalisation bench draws
them: a short pure delay (below one JND), a gain that differs with the direction of
motion, a backlash wider than the bench's range.

Each recording is a clean simulated follower recording (`synthetic.follower_recording`)
whose true, noise-free force gets a planted deviation in closed form, the sensors'
noise on top; the reference is the oracle, eq. 1 plus the exact deviation as one more
column fitted on the training block (`general.oracle_rmse`'s rule).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from teleop_core.calibration import Calibrator, FollowerBase
from teleop_core.calibration.models import CalibrationData
from teleop_core.calibration.synthetic import JND_N, follower_recording

Shape = Callable[[dict[str, np.ndarray]], np.ndarray]


def planted(
    deviation: Shape,
    seed: int,
    size_jnd: float | None = None,
    seconds: float = 60.0,
    rate_hz: float = 200.0,
) -> tuple[CalibrationData, float]:
    """A clean recording whose true force gets `deviation(true)` (scaled to `size_jnd`
    JND RMS, or as it is), and the oracle's held-out RMSE."""
    true: dict = {}
    rec, _ = follower_recording(seconds, (), rate_hz=rate_hz, seed=seed, noise_free=true)
    data = FollowerBase().data(rec)
    d = deviation(true)
    if size_jnd is not None:
        d = size_jnd * JND_N * d / np.sqrt(np.mean(d**2))
    y = data.y + d
    X = np.column_stack([FollowerBase().columns(data.signals), d])
    cut = round(0.75 * len(y))
    coef, *_ = np.linalg.lstsq(X[:cut], y[:cut], rcond=None)
    oracle = float(np.sqrt(np.mean((y[cut:] - X[cut:] @ coef) ** 2)))
    return CalibrationData(data.signals, y, f"planted (seed {seed}, simulated)"), oracle


def names(report: dict) -> list[str]:
    return [e["family"] for e in report["effects_added"]] + [
        t["term"] for t in report["discovered_terms"]
    ]


def delayed(lag_s: float) -> Shape:
    """The whole true force taken lag_s earlier, minus the force: a pure delay."""
    return lambda s: np.interp(s["t"] - lag_s, s["t"], s["force"]) - s["force"]


@pytest.mark.parametrize("seed", [1, 2])
def test_a_15_ms_delay_below_one_jnd_is_named_delay(seed: int) -> None:
    data, oracle = planted(delayed(0.015), seed)
    report = Calibrator(FollowerBase()).fit(data).report()
    assert names(report) == ["delay"]
    assert report["ambiguous_effects"] == []
    (delay,) = report["effects_added"]
    assert delay["params"]["lag_s"] == pytest.approx(0.015, abs=1e-9)
    assert report["rmse_after"] <= 1.05 * oracle
