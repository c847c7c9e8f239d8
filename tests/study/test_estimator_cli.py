"""`study estimator train/run` and `study bench follower` end to end, on small data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.cli import main
from teleop_core.estimation.estimator import MODEL_FILES
from tests.study.conftest import assert_figures, one_error_line
from tests.teleop_core.conftest import simulate_recording


@pytest.fixture(scope="module")
def recording_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "bench.csv"
    simulate_recording(30.0, seed=3).to_csv(path)
    return path


@pytest.fixture(scope="module")
def model_dir(recording_csv: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("models") / "m"
    status = main(
        [
            "estimator",
            "train",
            str(recording_csv),
            "--out",
            str(out),
            "--window",
            "6",
            "--epochs",
            "2",
            "--hidden-size",
            "8",
            "--seed",
            "1",
            "--effects",
            "none",
        ]
    )
    assert status == 0
    return out


def test_train_writes_the_model_folder_with_a_summary(model_dir: Path) -> None:
    written = sorted(p.name for p in model_dir.iterdir())
    assert written == sorted([*MODEL_FILES, "gru.npz", "gru.pt"])
    summary = json.loads((model_dir / "summary.json").read_text())
    assert summary["window"] == 6
    assert summary["epochs_run"] == 2
    assert (
        set(summary["train_rmse_n"])
        == set(summary["validation_rmse_n"])
        == {"physics", "hybrid", "final"}
    )
    std = json.loads((model_dir / "standardisation.json").read_text())
    # [I_q, theta_d, theta_dd] and the default memory features: 2 inputs x 4 time constants
    assert len(std["feature_mean"]) == len(std["feature_std"]) == 3 + 8
    assert std["memory"]["kind"] == "ema_residual"
    assert std["features"][:4] == ["iq", "omega", "alpha", "iq-ema0.1s"]


def test_run_writes_one_estimate_per_full_window(
    model_dir: Path, recording_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "pred.csv"
    assert main(["estimator", "run", str(model_dir), str(recording_csv), "--out", str(out)]) == 0
    pred = pd.read_csv(out)
    rows = len(pd.read_csv(recording_csv))
    assert list(pred.columns) == ["t", "f_ref", "f_physics", "f_hybrid", "f_final", "in_range"]
    assert len(pred) == rows - 6 + 1
    assert "RMSE against f_ref" in capsys.readouterr().out


def test_run_flags_the_estimates_whose_inputs_leave_the_training_range(
    model_dir: Path, recording_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same drive three times as fast. Every sample faster than
    anything in the whole training recording must be flagged, and the summary line gives
    the share the column holds."""
    fast = pd.read_csv(recording_csv)
    for column in ("theta", "omega", "alpha"):
        fast[column] *= 3.0
    fast.to_csv(tmp_path / "fast.csv", index=False)
    out = tmp_path / "pred.csv"
    argv = ["estimator", "run", str(model_dir), str(tmp_path / "fast.csv"), "--out", str(out)]
    assert main(argv) == 0
    pred = pd.read_csv(out)
    trained_on = pd.read_csv(recording_csv)
    beyond = (fast["omega"].abs() > trained_on["omega"].abs().max()).to_numpy()[6 - 1 :]
    assert beyond.mean() > 0.2
    assert (pred["in_range"][beyond] == 0).all()
    share = 100 * (1 - pred["in_range"].mean())
    assert f"outside the training range: {share:.1f} % of the estimates" in capsys.readouterr().out


def test_memory_none_trains_the_plain_window_and_runs(
    recording_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "plain"
    argv = [
        "estimator",
        "train",
        str(recording_csv),
        "--out",
        str(out),
        "--window",
        "6",
        "--epochs",
        "1",
        "--hidden-size",
        "4",
        "--memory",
        "none",
    ]
    assert main(argv) == 0
    std = json.loads((out / "standardisation.json").read_text())
    assert std["memory"]["kind"] == "none"
    assert std["features"] == ["iq", "omega", "alpha"]
    assert len(std["feature_mean"]) == 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["config"]["memory"]["time_constants_s"] == []
    pred = tmp_path / "pred.csv"
    assert main(["estimator", "run", str(out), str(recording_csv), "--out", str(pred)]) == 0
    assert len(pd.read_csv(pred)) == len(pd.read_csv(recording_csv)) - 6 + 1
    line = one_error_line(capsys, [*argv[:-1], "fast", "--force"])
    assert "--memory 'fast'" in line


def test_a_model_whose_memory_and_weights_disagree_is_one_line(
    model_dir: Path, recording_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    broken = tmp_path / "m"
    shutil.copytree(model_dir, broken)
    std = json.loads((broken / "standardisation.json").read_text())
    std["memory"] = {"kind": "none", "columns": [], "time_constants_s": []}
    (broken / "standardisation.json").write_text(json.dumps(std))
    pred = tmp_path / "pred.csv"
    line = one_error_line(
        capsys, ["estimator", "run", str(broken), str(recording_csv), "--out", str(pred)]
    )
    assert "its network takes 11 inputs per step" in line
    assert not pred.exists()


def test_bad_recording_is_one_line_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], recording_csv: Path
) -> None:
    bad = tmp_path / "bad.csv"
    lines = recording_csv.read_text().splitlines()
    lines[40] = lines[40].replace(lines[40].split(",")[1], "oops", 1)
    bad.write_text("\n".join(lines) + "\n")
    line = one_error_line(capsys, ["estimator", "train", str(bad), "--out", str(tmp_path / "m")])
    assert "line 41, column 'iq': 'oops' is not a finite number" in line
    assert not (tmp_path / "m").exists()


def test_existing_model_folder_is_not_overwritten_without_force(
    model_dir: Path, recording_csv: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    line = one_error_line(
        capsys, ["estimator", "train", str(recording_csv), "--out", str(model_dir)]
    )
    assert "exists and is not empty" in line


def test_run_with_a_missing_model_is_one_line(
    tmp_path: Path, recording_csv: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "pred.csv"
    line = one_error_line(
        capsys, ["estimator", "run", str(tmp_path / "none"), str(recording_csv), "--out", str(out)]
    )
    assert "model folder" in line
    assert "does not exist" in line
    assert not out.exists()


def test_bench_follower_quick_writes_every_table(tmp_path: Path) -> None:
    out_json = tmp_path / "follower.json"
    assert (
        main(
            [
                "bench",
                "follower",
                "--quick",
                "--json",
                str(out_json),
                "--out",
                str(tmp_path / "fig"),
            ]
        )
        == 0
    )
    report = json.loads(out_json.read_text())
    assert report["data"].startswith("SIMULATED")  # no measured data in this bench
    assert set(report["table_i"]) == {"ramp", "step"}
    assert set(report["table_ii"]) == {"0.5", "1", "1.5", "2", "2.5", "3"}
    assert set(report["table_iii"]["pooled"]) == {
        "hybrid",
        "final",
        "direct",
        "physics",
        "baseline",
    }
    assert set(report["window_sweep"]) == {"2", "5"}
    assert report["timing"]["median_ms"] > 0
    # the training time: the command's defaults, with early stopping and with every epoch
    runs = report["training_time"]["runs"]
    assert runs["all_epochs"]["epochs_run"] == 2
    assert runs["all_epochs"]["patience"] is None
    assert runs["default"]["patience"] == 10
    assert runs["default"]["samples"] == report["training"]["samples"]
    for run in runs.values():
        assert 0 < run["seconds_to_first_epoch_end"] < run["seconds"]
    gen = report["generalisation"]
    assert "simulated" in gen["data"]
    assert all("simulated" in r["data"] for r in gen["runs"])
    assert {(r["effect"], r["seed"]) for r in gen["runs"]} == {("stribeck", 0), ("drift", 0)}
    runs = json.loads((tmp_path / "fig" / "generalisation_runs.json").read_text())
    assert [r["effect"] for r in runs] == ["stribeck", "drift"]
    for r in gen["runs"]:
        e = r["test_rmse_n"]
        assert r["hybrid_over_physics"] == pytest.approx(e["hybrid"] / e["physics"])
    assert "simulated" in (tmp_path / "fig" / "follower_bench.md").read_text()
    assert_figures(
        tmp_path / "fig",
        "table_i_velocity.png",
        "table_ii_fig6.png",
        "table_iii_fig9.png",
        "fig8_window.png",
    )


def _without_torch(monkeypatch: pytest.MonkeyPatch) -> None:
    """PyTorch as not installed (the `train` extra left out): `import torch` fails, and the
    modules that imported it are imported again."""
    import sys

    import teleop_core.estimation as package

    monkeypatch.setitem(sys.modules, "torch", None)
    for name in ("gru_torch", "training"):
        monkeypatch.delitem(sys.modules, f"teleop_core.estimation.{name}", raising=False)
        monkeypatch.delattr(package, name, raising=False)


def test_training_without_pytorch_is_one_line_naming_the_extra(
    recording_csv: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    _without_torch(monkeypatch)
    out = tmp_path / "m"
    line = one_error_line(capsys, ["estimator", "train", str(recording_csv), "--out", str(out)])
    assert "needs PyTorch" in line, line
    assert "pip install 'haptic-study[train]'" in line, line
    assert not out.exists()


def test_without_pytorch_a_trained_model_runs_and_saves_without_gru_pt(
    model_dir: Path, recording_csv: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from teleop_core.estimation.estimator import ForceEstimator
    from teleop_core.follower.recording import FollowerRecording

    _without_torch(monkeypatch)
    estimator = ForceEstimator.load(model_dir)  # reads gru.npz
    recording = FollowerRecording.from_csv(recording_csv)
    before = estimator.predict(recording).f_final
    estimator.save(tmp_path / "copy", {"note": "saved without PyTorch"})
    assert not (tmp_path / "copy" / "gru.pt").exists()
    again = ForceEstimator.load(tmp_path / "copy").predict(recording).f_final
    np.testing.assert_array_equal(again, before)
