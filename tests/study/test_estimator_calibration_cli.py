"""`study estimator train --calibration REPORT.json`, on small data."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from study.cli import main
from tests.teleop_core.conftest import calibrated_folder


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory):
    return calibrated_folder(tmp_path_factory.mktemp("ext"), ["position_periodic"], 30.0, 8)


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
