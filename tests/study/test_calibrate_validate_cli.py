"""`study calibrate --validate` and `--units`, and `study estimator train --validate`: a
model fitted on one recording predicts another in full, the report says how it does,
a torque recording reports N m, and a validation recording that breaks the contract is
refused before anything is written.

The references are independent of the command's own arithmetic: the calibrated model
rebuilt from the report's JSON (`CalibratedModel.from_dict`) and run over the
validation recording, MATLAB `compare`'s fit computed here from its definition, the
closed-form rigid axis a recording was simulated from, and `study estimator run` over
the same file.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from study.cli import main
from teleop_core.calibration.fitting import CalibratedModel
from teleop_core.calibration.models import FollowerBase
from teleop_core.calibration.rigid_axis import RigidAxisBase
from teleop_core.calibration.synthetic import follower_recording
from tests.study.conftest import one_error_line

VALIDATION_KEYS = {"recording", "rmse_base", "rmse_final", "fit_percent", "samples"}


def _rigid_axis(
    path: Path,
    amplitude: float,
    frequency_hz: float,
    seed: int,
    columns: tuple[str, str],
    reverse_viscous: float = 0.0,
) -> None:
    """A rigid axis u = M q'' + Fv q' + Fc sgn(q') + offset (M 2.0, Fv 5.0, Fc 1.5,
    offset 0.3), plus `reverse_viscous` q' more viscous friction while q' < 0, driven by
    two sines that start and end at rest (a 1 s sin^2 taper at each end), 500 Hz for
    8 s, noise SD 0.05 on u and 1e-6 on q (SIMULATED): the same machine at another
    amplitude and speed for another seed. The derivatives are central differences on a
    200x finer grid (relative error below 1e-6)."""
    rng = np.random.default_rng(seed)
    fine = np.arange(8 * 500 * 200) / (500.0 * 200)
    w1, w2 = 2 * np.pi * frequency_hz, 2 * np.pi * 2.7 * frequency_hz
    taper = np.sin(0.5 * np.pi * np.clip(np.minimum(fine, fine[-1] - fine), 0.0, 1.0)) ** 2
    q_fine = amplitude * taper * (np.sin(w1 * fine) + 0.3 * np.sin(w2 * fine + 1.0))
    qd_fine = np.gradient(q_fine, fine)
    qdd_fine = np.gradient(qd_fine, fine)
    t, q, qd, qdd = (v[::200] for v in (fine, q_fine, qd_fine, qdd_fine))
    u = 2.0 * qdd + 5.0 * qd + 1.5 * np.sign(qd) + 0.3 + rng.normal(0.0, 0.05, len(t))
    u += reverse_viscous * np.minimum(qd, 0.0)
    q_name, u_name = columns
    frame = {"t": t, q_name: q + rng.normal(0.0, 1e-6, len(t)), u_name: u}
    pd.DataFrame(frame).to_csv(path, index=False)


def _true_rmse(
    path: Path, report: dict[str, Any], axis: str, reverse_viscous: float = 0.0
) -> float:
    """RMSE of the true model of `_rigid_axis` over `path`, on the velocity and
    acceleration the calibration derives there (the training recording's cutoff): what
    knowing the machine exactly would leave (the noise, and the derivatives' error at
    the reversals and the ends)."""
    cutoff = report["preparation"]["derivative_cutoff_hz"]
    data = RigidAxisBase(cutoff_hz=cutoff, axis=axis).read(path)
    qd, qdd = data.signals["speed"], data.signals["accel"]
    u = 2.0 * qdd + 5.0 * qd + 1.5 * np.sign(qd) + 0.3 + reverse_viscous * np.minimum(qd, 0.0)
    return float(np.sqrt(np.mean((data.y - u) ** 2)))


def _calibrate(folder: Path, recording: Path, *extra: str) -> int:
    return main(
        [
            "calibrate",
            str(recording),
            "--json",
            str(folder / "report.json"),
            "--predictions",
            str(folder / "pred.csv"),
            "--out",
            str(folder / "figs"),
            *extra,
        ]
    )


@pytest.fixture(scope="module")
def follower(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """Calibrated on one SIMULATED follower session with a direction asymmetry, validated
    on two others of the same drive (other seeds: other sessions)."""
    folder = tmp_path_factory.mktemp("val")
    for name, seed in (("train", 5), ("other", 6), ("third", 8)):
        rec, _ = follower_recording(30.0, ["direction_asymmetry"], seed=seed)
        rec.to_csv(folder / f"{name}.csv")
    from click.testing import CliRunner

    from study.cli import cli

    result = CliRunner().invoke(
        cli,
        [
            "calibrate",
            str(folder / "train.csv"),
            "--json",
            str(folder / "report.json"),
            "--predictions",
            str(folder / "pred.csv"),
            "--out",
            str(folder / "figs"),
            "--validate",
            str(folder / "other.csv"),
            "--validate",
            str(folder / "third.csv"),
        ],
    )
    assert result.exit_code == 0, result.output
    return folder, result.output


def test_each_validation_recording_gets_an_entry_with_the_contract_keys(
    follower: tuple[Path, str],
) -> None:
    folder, _ = follower
    report = json.loads((folder / "report.json").read_text())
    entries = report["validation"]
    assert [e["recording"] for e in entries] == [
        str(folder / "other.csv"),
        str(folder / "third.csv"),
    ]
    for entry in entries:
        assert set(entry) == VALIDATION_KEYS
        assert entry["samples"] == 3000  # every sample: 30 s at 100 Hz
        # the effect found on the training session carries to the others (each session
        # draws its own asymmetry's size, so not all of it)
        assert entry["rmse_final"] < entry["rmse_base"], entry


def test_the_validation_rmse_and_fit_are_the_models_own_on_the_whole_recording(
    follower: tuple[Path, str],
) -> None:
    """Rebuilt from the report's JSON, the calibrated model predicts the validation
    recording; its RMSE and MATLAB's NRMSE fit, computed here, are the report's."""
    folder, _ = follower
    report = json.loads((folder / "report.json").read_text())
    model = CalibratedModel.from_dict(report["calibrated_model"])
    assert [e["family"] for e in report["calibrated_model"]["effects"]] == ["direction_asymmetry"]
    data = FollowerBase().read(folder / "other.csv")
    e = data.y - model.predict(data)
    entry = report["validation"][0]
    assert entry["rmse_final"] == pytest.approx(float(np.sqrt(np.mean(e**2))), rel=1e-9)
    # fit = 100 (1 - ||y - y_hat|| / ||y - mean(y)||)   (MATLAB compare, NRMSE)
    fit = 100.0 * (1.0 - np.linalg.norm(e) / np.linalg.norm(data.y - data.y.mean()))
    assert entry["fit_percent"] == pytest.approx(fit, rel=1e-9)


def test_the_summary_and_a_figure_say_how_the_model_does_on_each(
    follower: tuple[Path, str],
) -> None:
    folder, output = follower
    report = json.loads((folder / "report.json").read_text())
    lines = [line for line in output.splitlines() if line.startswith("validation ")]
    assert len(lines) == 2
    first = report["validation"][0]
    assert str(folder / "other.csv") in lines[0]
    assert f"{first['rmse_final']:.4f} N" in lines[0]
    assert f"fit {first['fit_percent']:.1f} %" in lines[0]
    assert (folder / "figs" / "validation.png").stat().st_size > 10_000


def test_without_validation_the_report_has_an_empty_list(tmp_path: Path) -> None:
    rec, _ = follower_recording(12.0, seed=2)
    rec.to_csv(tmp_path / "rec.csv")
    assert _calibrate(tmp_path, tmp_path / "rec.csv", "--max-effects", "0") == 0
    assert json.loads((tmp_path / "report.json").read_text())["validation"] == []
    assert not (tmp_path / "figs" / "validation.png").exists()


def test_a_validation_recording_that_breaks_the_contract_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec, _ = follower_recording(12.0, seed=2)
    rec.to_csv(tmp_path / "rec.csv")
    frame = pd.read_csv(tmp_path / "rec.csv").drop(columns=["f_ref"])
    frame.to_csv(tmp_path / "bad.csv", index=False)
    out = tmp_path / "out"
    out.mkdir()
    line = one_error_line(
        capsys,
        [
            "calibrate",
            str(tmp_path / "rec.csv"),
            "--json",
            str(out / "r.json"),
            "--predictions",
            str(out / "p.csv"),
            "--out",
            str(out / "figs"),
            "--validate",
            str(tmp_path / "bad.csv"),
        ],
    )
    assert "bad.csv" in line
    assert "f_ref" in line
    assert list(out.iterdir()) == []


def test_a_rotary_axis_reports_n_m_and_names_its_axis(tmp_path: Path) -> None:
    """Columns q_rad, u_n_m: a rotary axis in the summary line, the JSON's units and
    parameter names, and the figures; trained at one speed, validated at a faster one
    of the same machine, the base model alone is the true one, so its error on the
    other recording is the noise's (SD 0.05 N m)."""
    _rigid_axis(tmp_path / "slow.csv", 0.5, 0.4, 1, ("q_rad", "u_n_m"))
    _rigid_axis(tmp_path / "fast.csv", 0.8, 0.9, 2, ("q_rad", "u_n_m"))
    from click.testing import CliRunner

    from study.cli import cli

    result = CliRunner().invoke(
        cli,
        [
            "calibrate",
            str(tmp_path / "slow.csv"),
            "--model",
            "rigid-axis",
            "--json",
            str(tmp_path / "report.json"),
            "--predictions",
            str(tmp_path / "pred.csv"),
            "--out",
            str(tmp_path / "figs"),
            "--validate",
            str(tmp_path / "fast.csv"),
            "--max-effects",
            "0",
        ],
    )
    assert result.exit_code == 0, result.output
    first = result.output.splitlines()[0]
    assert "N m ->" in first
    assert first.endswith("effects added: none")
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["units"] == {"axis": "rotary", "output": "N m", "position": "rad"}
    params = report["base_params"]["params"]
    assert list(params) == [
        "inertia_kg_m2",
        "viscous_friction_n_m_s_per_rad",
        "coulomb_friction_n_m",
        "offset_n_m",
    ]
    assert params["inertia_kg_m2"] == pytest.approx(2.0, rel=0.02)
    assert params["coulomb_friction_n_m"] == pytest.approx(1.5, rel=0.05)
    (entry,) = report["validation"]
    assert entry["samples"] == 4000
    true = _true_rmse(tmp_path / "fast.csv", report, "rotary")
    assert true <= entry["rmse_final"] <= 1.1 * true, (entry, true)
    assert "N m (calibrated)" in result.output


def test_an_effect_found_at_one_speed_carries_to_another(tmp_path: Path) -> None:
    """A linear axis with more viscous friction in reverse (3 N s/m): calibrated on a
    slow recording, the direction asymmetry it adds predicts a faster one of the same
    machine to the noise (SD 0.05 N), where the base model alone errs by more than
    twice that; the figure is drawn from the validation recording."""
    _rigid_axis(tmp_path / "slow.csv", 0.5, 0.4, 1, ("q", "u"), reverse_viscous=3.0)
    _rigid_axis(tmp_path / "fast.csv", 0.8, 0.9, 2, ("q", "u"), reverse_viscous=3.0)
    status = _calibrate(
        tmp_path,
        tmp_path / "slow.csv",
        *("--model", "rigid-axis", "--validate", str(tmp_path / "fast.csv")),
        *("--families", "direction_asymmetry"),
    )
    assert status == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["units"] == {"axis": "linear", "output": "N", "position": "m"}
    assert [e["family"] for e in report["effects_added"]] == ["direction_asymmetry"]
    (entry,) = report["validation"]
    true = _true_rmse(tmp_path / "fast.csv", report, "linear", reverse_viscous=3.0)
    assert true <= entry["rmse_final"] <= 1.1 * true, (entry, true)
    assert entry["rmse_base"] > 3.0 * entry["rmse_final"], entry
    assert (tmp_path / "figs" / "validation.png").exists()


def test_the_rigid_axis_figures_name_the_axis_in_its_units() -> None:
    from study.analysis.calibration_figures import quantity_label, signal_labels

    assert signal_labels("rigid-axis", "m")["angle"] == "position q (m)"
    assert signal_labels("rigid-axis", "rad")["speed"] == "velocity q' (rad/s)"
    assert quantity_label("speed band", "rigid-axis", "N m", "rad") == "|velocity q'| (rad/s)"
    # the follower's wheel keeps its own labels
    assert signal_labels("follower")["angle"] == "wheel angle (rad)"


def test_units_that_contradict_the_columns_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _rigid_axis(tmp_path / "rec.csv", 0.5, 0.4, 1, ("q_rad", "u_n_m"))
    out = tmp_path / "out"
    out.mkdir()
    argv = [
        "calibrate",
        str(tmp_path / "rec.csv"),
        "--model",
        "rigid-axis",
        "--json",
        str(out / "r.json"),
        "--predictions",
        str(out / "p.csv"),
        "--out",
        str(out / "figs"),
    ]
    line = one_error_line(capsys, [*argv, "--units", "linear"])
    assert "'q_rad'" in line
    assert "rotary" in line
    _rigid_axis(tmp_path / "mixed.csv", 0.5, 0.4, 1, ("q_rad", "u_n"))
    argv[1] = str(tmp_path / "mixed.csv")
    assert "different units" in one_error_line(capsys, argv)
    follower_recording(12.0, seed=2)[0].to_csv(tmp_path / "f.csv")
    argv[1:4] = [str(tmp_path / "f.csv"), "--model", "follower"]
    assert "--units" in one_error_line(capsys, [*argv, "--units", "rotary"])
    assert list(out.iterdir()) == []


def test_a_validation_recording_of_another_axis_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _rigid_axis(tmp_path / "rec.csv", 0.5, 0.4, 1, ("q_m", "u_n"))
    _rigid_axis(tmp_path / "rot.csv", 0.5, 0.4, 1, ("q_rad", "u_n_m"))
    out = tmp_path / "out"
    out.mkdir()
    argv = ["calibrate", str(tmp_path / "rec.csv"), "--model", "rigid-axis"]
    argv += ["--json", str(out / "r.json"), "--predictions", str(out / "p.csv")]
    argv += ["--out", str(out / "figs"), "--validate", str(tmp_path / "rot.csv")]
    line = one_error_line(capsys, argv)
    assert "rot.csv" in line
    assert "linear" in line
    assert list(out.iterdir()) == []


def test_the_estimator_validates_on_another_recording(tmp_path: Path) -> None:
    """`study estimator train --validate`: summary.json's entry holds the RMSEs that
    `study estimator run` prints for the same model over the same file."""
    for name, seed in (("train", 3), ("other", 4)):
        follower_recording(20.0, seed=seed)[0].to_csv(tmp_path / f"{name}.csv")
    from click.testing import CliRunner

    from study.cli import cli

    runner = CliRunner()
    model = tmp_path / "m"
    train = runner.invoke(
        cli,
        [
            *("estimator", "train", str(tmp_path / "train.csv"), "--out", str(model)),
            *("--window", "6", "--epochs", "2", "--hidden-size", "8", "--effects", "none"),
            *("--validate", str(tmp_path / "other.csv")),
        ],
    )
    assert train.exit_code == 0, train.output
    (entry,) = json.loads((model / "summary.json").read_text())["validation"]
    assert set(entry) == VALIDATION_KEYS
    assert entry["samples"] == 2000 - 6 + 1  # one estimate per full window
    run = runner.invoke(
        cli,
        [
            "estimator",
            "run",
            str(model),
            str(tmp_path / "other.csv"),
            "--out",
            str(tmp_path / "o.csv"),
        ],
    )
    assert run.exit_code == 0, run.output
    assert f"physics {entry['rmse_base']:.4f} N" in run.output
    assert f"after EKF {entry['rmse_final']:.4f} N" in run.output
    assert f"validation {tmp_path / 'other.csv'}" in train.output


def test_the_estimator_refuses_a_bad_validation_recording_before_training(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    follower_recording(12.0, seed=3)[0].to_csv(tmp_path / "train.csv")
    (tmp_path / "bad.csv").write_text("t,iq\n0,1\n")
    line = one_error_line(
        capsys,
        [
            *("estimator", "train", str(tmp_path / "train.csv"), "--out", str(tmp_path / "m")),
            *("--validate", str(tmp_path / "bad.csv")),
        ],
    )
    assert "bad.csv" in line
    assert not (tmp_path / "m").exists()
