"""`study calibrate` end to end: the report's keys, the predictions' columns, the figures,
and refusals that leave nothing behind."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.cli import main
from teleop_core.calibration.synthetic import follower_recording, master_recording
from teleop_core.notes.params import default_params
from teleop_core.notes.simulate import simulate_recording

REPORT_KEYS = {
    "rmse_before",
    "rmse_after",
    "effects_added",
    "candidates_rejected",
    "residual_tests_before",
    "residual_tests_after",
}


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("cal")
    rec, _ = follower_recording(40.0, ["direction_asymmetry"], seed=5)
    rec.to_csv(folder / "rec.csv")
    status = main(
        [
            "calibrate",
            str(folder / "rec.csv"),
            "--model",
            "follower",
            "--json",
            str(folder / "report.json"),
            "--predictions",
            str(folder / "pred.csv"),
            "--out",
            str(folder / "figs"),
        ]
    )
    assert status == 0
    return folder


def test_report_has_the_contract_keys(calibrated: Path) -> None:
    report = json.loads((calibrated / "report.json").read_text())
    assert REPORT_KEYS <= set(report)
    assert report["rmse_after"] < report["rmse_before"]
    (effect,) = report["effects_added"][:1]
    assert set(effect) == {
        "family",
        "params",
        "ci",
        "rmse_after_step",
        "share_of_explained_variance",
    }
    # the shares of the steps add up to the whole held-out MSE cut
    shares = [e["share_of_explained_variance"] for e in report["effects_added"]]
    shares += [e["share_of_explained_variance"] for e in report["discovered_terms"]]
    assert sum(shares) == pytest.approx(1.0)
    assert effect["family"] == "direction_asymmetry"
    assert set(effect["params"]) == set(effect["ci"])
    for value, (lo, hi) in zip(effect["params"].values(), effect["ci"].values(), strict=True):
        assert lo <= value <= hi
    rejected = {c["family"] for c in report["candidates_rejected"]}
    assert "direction_asymmetry" not in rejected
    assert len(rejected) >= 1
    for key in ("residual_tests_before", "residual_tests_after"):
        assert {"ljung_box", "autocorrelation", "cross_correlation"} <= set(report[key])


def test_predictions_cover_the_held_out_block(calibrated: Path) -> None:
    pred = pd.read_csv(calibrated / "pred.csv")
    assert list(pred.columns) == ["t", "f_ref", "f_base", "f_final"]
    report = json.loads((calibrated / "report.json").read_text())
    assert len(pred) == report["held_out"]["samples"]
    assert pred["t"].iloc[0] == pytest.approx(report["held_out"]["start_s"])
    # the report's RMSEs are those of the predictions file
    rmse = np.sqrt(np.mean((pred["f_final"] - pred["f_ref"]) ** 2))
    assert rmse == pytest.approx(report["rmse_after"], rel=1e-6)


def test_figures_are_written(calibrated: Path) -> None:
    names = {p.name for p in (calibrated / "figs").iterdir()}
    report = json.loads((calibrated / "report.json").read_text())
    # the unexplained quantity's figure only when the verdict names one
    remains = {"residual_vs_unexplained.png"} if report["verdict"] == "structure_remains" else set()
    assert names == {
        "residual_blocks.png",
        "residual_vs_t.png",
        "residual_vs_speed.png",
        "residual_vs_angle.png",
        "residual_acf.png",
        *remains,
    }


def test_master_model_reads_its_own_contract(tmp_path: Path) -> None:
    t, i, f = master_recording(30.0, seed=2)
    pd.DataFrame({"t": t, "current_ma": i, "f_ref": f}).to_csv(tmp_path / "dial.csv", index=False)
    args = ["calibrate", str(tmp_path / "dial.csv"), "--model", "master"]
    out = ["--json", str(tmp_path / "r.json"), "--predictions", str(tmp_path / "p.csv")]
    assert main([*args, *out, "--out", str(tmp_path / "figs")]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["effects_added"][0]["family"] == "hysteresis"
    remains = {"residual_vs_unexplained.png"} if report["verdict"] == "structure_remains" else set()
    assert {p.name for p in (tmp_path / "figs").iterdir()} == {
        "residual_blocks.png",
        "residual_vs_t.png",
        "residual_vs_drive.png",
        "residual_acf.png",
        *remains,
    }


def test_a_bad_recording_is_refused_and_nothing_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "bad.csv").write_text("t,iq,theta,omega\n0,0,0,0\n")
    args = ["calibrate", str(tmp_path / "bad.csv"), "--json", str(tmp_path / "r.json")]
    status = main([*args, "--predictions", str(tmp_path / "p.csv"), "--out", str(tmp_path / "f")])
    assert status == 2
    err = capsys.readouterr().err
    assert "study calibrate: error:" in err
    assert "'f_ref' missing" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


def test_notes_rotation_ramp_names_the_ccw_loss(tmp_path: Path) -> None:
    frame = simulate_recording(
        default_params("rotation"), "ramp", "clamped", noise=0.02, seed=4, rate_hz=200.0
    )
    frame.to_csv(tmp_path / "ramp.csv", index=False)
    args = ["calibrate", str(tmp_path / "ramp.csv"), "--model", "notes-rotation"]
    out = ["--json", str(tmp_path / "r.json"), "--predictions", str(tmp_path / "p.csv")]
    assert main([*args, *out, "--out", str(tmp_path / "figs")]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    added = {e["family"]: e for e in report["effects_added"]}
    assert {"hysteresis", "direction_asymmetry"} <= set(added)
    assert "reverse_loss" in added["direction_asymmetry"]["params"]
    assert report["model"] == "notes-rotation"
