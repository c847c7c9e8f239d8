"""`study estimator train --calibration REPORT.json` (issue 10, point 5), on small data."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from study.cli import main
from teleop_core.calibration import Calibrator, FollowerBase
from teleop_core.calibration.synthetic import follower_recording


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("ext")
    rec, _ = follower_recording(30.0, ["position_periodic"], seed=8)
    rec.to_csv(folder / "rec.csv")
    model = FollowerBase()
    report = Calibrator(model).fit(model.data(rec)).report()
    (folder / "report.json").write_text(json.dumps(report))
    return folder, rec, report


def test_estimator_train_cli_takes_a_calibration(calibrated, tmp_path: Path) -> None:
    folder, _, _ = calibrated
    args = ["estimator", "train", str(folder / "rec.csv"), "--out", str(tmp_path / "m")]
    small = ["--window", "6", "--epochs", "1", "--hidden-size", "8"]
    assert main([*args, *small, "--calibration", str(folder / "report.json")]) == 0
    assert (tmp_path / "m" / "calibration.json").is_file()
    summary = json.loads((tmp_path / "m" / "summary.json").read_text())
    assert any("position_periodic" in note for note in summary["notes"])


def test_a_master_report_is_refused(calibrated, tmp_path: Path, capsys) -> None:
    folder, _, report = calibrated
    master = {
        **report,
        "calibrated_model": {**report["calibrated_model"], "base": "master", "base_settings": {}},
    }
    (tmp_path / "master.json").write_text(json.dumps(master))
    args = ["estimator", "train", str(folder / "rec.csv"), "--out", str(tmp_path / "m")]
    status = main([*args, "--epochs", "1", "--calibration", str(tmp_path / "master.json")])
    assert status == 2
    assert "needs --model follower" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()
