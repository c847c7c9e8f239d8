"""`study simulate` and `study bench lcca` end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from study.cli import main
from tests.teleop_core.conftest import simulate_recording


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    base = tmp_path_factory.mktemp("est")
    simulate_recording(30.0, seed=5).to_csv(base / "bench.csv")
    argv = ["estimator", "train", str(base / "bench.csv"), "--out", str(base / "m")]
    # eq. 1 + GRU: a model the loop can run (one with effects runs over recordings)
    small = ["--epochs", "2", "--hidden-size", "8", "--window", "6", "--effects", "none"]
    assert main([*argv, *small]) == 0
    return base / "m"


def test_simulate_writes_samples_summary_and_figure(
    model_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "trial.csv"
    argv = ["simulate", "--task", "lcca", "--group", "expert", "--condition", "HV", "--seed", "1"]
    argv += ["--out", str(out), "--plot", str(tmp_path / "t.png"), "--estimator", str(model_dir)]
    assert main(argv) == 0
    frame = pd.read_csv(out)
    proximal = [c for c in frame.columns if "proximal" in c]
    distal = [c for c in frame.columns if "distal" in c]
    assert proximal == ["proximal_force_n"]
    assert distal == ["distal_force_n"]
    summary = json.loads(out.with_suffix(".json").read_text())
    assert summary["peak_proximal_force_n"] == pytest.approx(frame["proximal_force_n"].max())
    assert summary["peak_distal_force_n"] == pytest.approx(frame["distal_force_n"].max())
    assert summary["completion_time_s"] == pytest.approx(frame["t_s"].iloc[-1])
    assert {"success", "wall_contacts", "group", "condition"} <= set(summary)
    assert summary["success"] == bool(frame["branch"].iloc[-1] == "left common carotid")
    assert (tmp_path / "t.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "peak proximal" in printed
    assert "wall contacts" in printed


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--group", "surgeon", "--condition", "HV"], "--group"),
        (["--group", "expert", "--condition", "HV", "--haptic-gain", "-1"], "haptic gain -1"),
        (["--group", "expert", "--condition", "HV", "--estimator", "/nonexistent"], "nonexistent"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(
    extra: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "trial.csv"
    assert main(["simulate", *extra, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert message in err[0]
    assert list(tmp_path.iterdir()) == []


def test_bench_lcca_quick_runs_the_design(model_dir: Path, tmp_path: Path) -> None:
    out_json = tmp_path / "lcca.json"
    argv = ["bench", "lcca", "--quick", "--json", str(out_json), "--out", str(tmp_path / "f")]
    assert main([*argv, "--estimator", str(model_dir)]) == 0
    report = json.loads(out_json.read_text())
    assert report["data"].startswith("SIMULATED")  # every figure and the JSON say so
    assert set(report["groups"]) == {"outsider", "novice", "expert"}
    assert {t["measure"] for t in report["tests"]} == {
        "completion_time_s",
        "peak_proximal_force_n",
        "peak_distal_force_n",
    }
    trials = pd.read_csv(tmp_path / "f" / "lcca_trials.csv")
    assert len(trials) == 12  # 2 per group, VO and HV
    assert (tmp_path / "f" / "lcca_tip_paths.png").stat().st_size > 10_000
