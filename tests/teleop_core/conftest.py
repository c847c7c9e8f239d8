"""Small simulated follower recordings shared by the estimation tests."""

from __future__ import annotations

import numpy as np
import pytest

from teleop_core.follower import scenarios
from teleop_core.follower.params import FollowerPlantParams, FollowerSensorParams
from teleop_core.follower.plant import FollowerDrive
from teleop_core.follower.recording import FollowerRecording
from teleop_core.follower.sensors import acquire


def simulate_recording(
    seconds: float,
    seed: int,
    plant: FollowerPlantParams | None = None,
    sensors: FollowerSensorParams | None = None,
) -> FollowerRecording:
    rng = np.random.default_rng(seed)
    cmd, load = scenarios.teleoperation(seconds, rng, max_load_n=1.6)
    trace = FollowerDrive(plant=plant or FollowerPlantParams()).run(cmd, load)
    return acquire(trace, sensors or FollowerSensorParams(), rng)


@pytest.fixture(scope="session")
def short_recording() -> FollowerRecording:
    """60 s of simulated navigation at 100 Hz (6,000 samples)."""
    return simulate_recording(60.0, seed=11)


@pytest.fixture(scope="session")
def small_estimator(short_recording: FollowerRecording):
    """A physics + GRU + EKF estimator trained for two epochs (loop tests need one)."""
    from teleop_core.estimation.gru import GruConfig
    from teleop_core.estimation.training import train_estimator

    estimator, _ = train_estimator(short_recording, GruConfig(max_epochs=2), seed=0)
    return estimator


def calibrated_folder(folder, effects: list[str], seconds: float, seed: int):
    """A simulated recording with `effects` written to folder/rec.csv and its
    calibration report to folder/report.json; returns (folder, recording, report)."""
    import json

    from teleop_core.calibration import Calibrator, FollowerBase
    from teleop_core.calibration.synthetic import follower_recording

    rec, _ = follower_recording(seconds, effects, seed=seed)
    rec.to_csv(folder / "rec.csv")
    model = FollowerBase()
    report = Calibrator(model).fit(model.data(rec)).report()
    (folder / "report.json").write_text(json.dumps(report))
    return folder, rec, report
