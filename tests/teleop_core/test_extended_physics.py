"""The estimator with a calibrated physics stage, on small data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.estimation.estimator import ForceEstimator
from teleop_core.estimation.extended import ExtendedPhysics
from teleop_core.estimation.gru import GruConfig
from teleop_core.estimation.training import train_estimator
from tests.teleop_core.conftest import calibrated_folder

TINY = GruConfig(window=6, hidden_size=8, max_epochs=1)


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory):
    return calibrated_folder(tmp_path_factory.mktemp("ext"), ["position_periodic"], 40.0, 8)


def test_extended_force_is_the_calibrated_prediction(calibrated) -> None:
    folder, rec, report = calibrated
    ext = ExtendedPhysics.read(folder / "report.json")
    assert ext.families == ["position_periodic"]
    # eq. 1's part is the report's refitted base parameters
    base = report["base_params"]["params"]
    assert ext.base.torque_constant_n_m_per_a == pytest.approx(base["torque_constant_n_m_per_a"])
    assert ext.base.offset_n == pytest.approx(base["offset_n"])
    # on the held-out block the extended force has the report's RMSE
    n_test = report["held_out"]["samples"]
    e = rec.f_ref[-n_test:] - ext.force(rec)[-n_test:]
    assert np.sqrt(np.mean(e**2)) == pytest.approx(report["rmse_after"], rel=1e-9)


def test_the_gru_gets_a_smaller_residual_and_the_model_round_trips(
    calibrated, tmp_path: Path
) -> None:
    _, rec, _ = calibrated
    ext = ExtendedPhysics.read(calibrated[0] / "report.json")
    _, plain = train_estimator(rec, TINY, seed=0)
    model, summary = train_estimator(rec, TINY, seed=0, extension=ext)
    assert summary.validation_rmse_n["physics"] < 0.5 * plain.validation_rmse_n["physics"]
    assert summary.validation_rmse_n["final"] < plain.validation_rmse_n["final"]
    model.save(tmp_path / "m", summary.to_dict())
    again = ForceEstimator.load(tmp_path / "m")
    assert again.extension is not None
    assert again.extension.families == ["position_periodic"]
    np.testing.assert_allclose(again.predict(rec).f_final, model.predict(rec).f_final)
    with pytest.raises(TeleopInputError, match="calibrated \\(position_periodic\\)"):
        again.stream()
