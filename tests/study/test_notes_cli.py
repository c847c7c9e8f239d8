"""NOTES end to end from the `study` command: characterise, identify, simulate, run."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pandas as pd
import pytest
from sqlalchemy import create_engine, text

from study.analysis.frames import trial_frame
from study.cli import main
from teleop_core.notes.params import RotationParams, TranslationParams
from teleop_core.notes.simulate import simulate_recording
from teleop_core.notes.tissue import TissueParams
from tests.conftest import expose_samples


def test_characterize_writes_json_figures_and_compensation(tmp_path: Path) -> None:
    out = tmp_path / "figs"
    assert (
        main(["characterize", "notes", "--json", str(tmp_path / "c.json"), "--out", str(out)]) == 0
    )
    data = json.loads((tmp_path / "c.json").read_text())
    assert set(data) == {"translation", "rotation"}
    for dof, paper_hz, limit in (("translation", 18.1, 5.62), ("rotation", 5.7, 0.19005)):
        axis = data[dof]
        assert {
            "bandwidth_hz",
            "settling_time_s",
            "max_continuous",
            "parameters",
            "fit_quality",
        } <= set(axis)
        assert axis["bandwidth_hz"] == pytest.approx(paper_hz, rel=0.1)
        assert axis["max_continuous"] == pytest.approx(limit, rel=0.005)
        comp = axis["compensation"]
        assert comp["after"]["hysteresis"] < 0.2 * comp["before"]["hysteresis"]
    assert data["rotation"]["compensation"]["before"]["asymmetry"] > 0.1
    assert abs(data["rotation"]["compensation"]["after"]["asymmetry"]) < 0.01
    assert {"notes_bode.png", "notes_ramp_compensation.png", "compensation.csv"} <= {
        p.name for p in out.iterdir()
    }
    table = pd.read_csv(out / "compensation.csv")
    assert list(table.columns) == ["dof", "measure", "before", "after"]


def test_identify_fits_an_open_chirp_and_measures_a_ramp(tmp_path: Path) -> None:
    truth = RotationParams().linear.scaled({"k_s": 1.15, "m_s": 0.9})
    chirp = simulate_recording(
        RotationParams().with_linear(truth), "chirp", "open", nonlinear=False
    )
    chirp.to_csv(tmp_path / "chirp.csv", index=False)
    argv = ["identify", "notes", str(tmp_path / "chirp.csv"), "--dof", "rotation"]
    assert main([*argv, "--json", str(tmp_path / "i.json")]) == 0
    fit = json.loads((tmp_path / "i.json").read_text())
    assert fit["experiment"] == "chirp"
    assert fit["boundary"] == "open"
    for name, value in zip(("m_m", "m_s", "k_s", "b_m", "b_s"), truth.as_tuple(), strict=True):
        assert fit["parameters"][name] == pytest.approx(value, rel=0.03)
    simulate_recording(TranslationParams(), "ramp", "clamped").to_csv(
        tmp_path / "r.csv", index=False
    )
    argv = ["identify", "notes", str(tmp_path / "r.csv"), "--dof", "translation"]
    assert main([*argv, "--json", str(tmp_path / "r.json")]) == 0
    ramp = json.loads((tmp_path / "r.json").read_text())
    assert ramp["max_continuous"] == pytest.approx(5.62, rel=0.005)


def test_identify_refuses_a_bad_file_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    frame = simulate_recording(TranslationParams(), "ramp", "clamped").iloc[:400].astype(object)
    frame.loc[7, "f_des"] = "n/a"
    frame.to_csv(tmp_path / "bad.csv", index=False)
    argv = ["identify", "notes", str(tmp_path / "bad.csv"), "--dof", "translation"]
    assert main([*argv, "--json", str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "bad.csv, row 9, column 'f_des'" in err
    assert not (tmp_path / "o.json").exists()


def test_simulate_notes_trial(tmp_path: Path) -> None:
    out = tmp_path / "n.csv"
    argv = ["simulate", "--task", "notes", "--group", "expert", "--condition", "HV", "--seed", "1"]
    assert main([*argv, "--out", str(out), "--plot", str(tmp_path / "n.png")]) == 0
    frame = pd.read_csv(out)
    summary = json.loads(out.with_suffix(".json").read_text())
    assert summary["task"] == "notes"
    assert summary["success"]
    assert summary["peak_force_demanded_n"] == pytest.approx(frame["force_demanded_n"].abs().max())
    assert summary["push_over_capacity_fraction"] == pytest.approx(
        (frame["force_demanded_n"] > 5.62).mean()
    )
    # the command is clipped at the continuous limit; inertia may add a little on top
    assert summary["peak_force_rendered_n"] < 5.62 * 1.15
    # the roll's torque: (R + c_r w) / eta at most, w up to the hand's fastest roll
    # (2 rad/s bounds every expert's), R the tissue's Coulomb level at the target
    tissue = TissueParams()
    bound = tissue.torque_level_n_m(0.2, True) + tissue.roll_damping_n_m_s_per_rad * 2.0
    assert summary["peak_torque_demanded_n_m"] <= bound / tissue.ccw_transmission
    assert summary["peak_torque_demanded_n_m"] == max(
        summary["peak_torque_cw_n_m"], summary["peak_torque_ccw_n_m"]
    )
    assert summary["peak_push_n"] == pytest.approx(frame["force_demanded_n"].max())
    assert summary["peak_pull_n"] == pytest.approx(-frame["force_demanded_n"].min())


def test_a_study_with_lcca_and_notes_runs_notes_blocks(tmp_path: Path) -> None:
    db = str(tmp_path / "s.db")
    (tmp_path / "d.toml").write_text(
        'name = "notes"\nseed = 3\ntrials_per_condition = 1\npractice_trials = 0\n'
        'tasks = ["notes"]\n[groups]\nexpert = 1\n'
    )
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    assert main(["participant", "add", "--group", "expert", "--db", db]) == 0
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    engine = create_engine(f"sqlite:///{db}")
    frame = trial_frame(engine)
    with sqlite3.connect(db) as raw:
        expose_samples(raw)
        # stored under the NOTES task's own columns, the demanded roll torque with them
        demanded = dict(
            raw.execute(
                "SELECT trial_id, MAX(ABS(force_demanded_n)) FROM samples GROUP BY trial_id"
            ).fetchall()
        )
        torque = dict(
            raw.execute(
                "SELECT trial_id, MAX(ABS(torque_demanded_n_m)) FROM samples GROUP BY trial_id"
            ).fetchall()
        )
        stored_columns = [r[1] for r in raw.execute("PRAGMA table_info(samples)")]
    with engine.connect() as conn:
        torque_peaks = dict(
            conn.execute(
                text(
                    "SELECT trial_id, value FROM trial_measures"
                    " WHERE name = 'peak_torque_demanded_n_m'"
                )
            ).all()
        )
    with engine.connect() as conn:
        stored = dict(
            conn.execute(
                text(
                    "SELECT trial_id, value FROM trial_measures"
                    " WHERE name = 'peak_force_demanded_n'"
                )
            ).all()
        )
    engine.dispose()
    assert list(frame["task"]) == ["notes", "notes"]
    assert sorted(frame["condition"]) == ["HV", "VO"]
    # NOTES measures under their own names, not in the LCCA's columns
    assert "peak_proximal_force_n" not in frame.columns
    assert frame["completion_time_s"].notna().all()
    assert frame["peak_force_demanded_n"].gt(0).all()
    assert frame["peak_tip_force_n"].notna().all()
    # the stored peak is the largest |demanded force| of the trial's stored samples
    assert stored.keys() == demanded.keys()
    assert len(stored) == 2
    for trial_id, value in stored.items():
        assert value == pytest.approx(demanded[trial_id])
        # the demanded torque's peak, once computed and dropped, is now in the samples
        assert torque_peaks[trial_id] == pytest.approx(torque[trial_id])
    assert "torque_demanded_n_m" in stored_columns
    assert "proximal_force_est_n" not in stored_columns  # no LCCA name for a NOTES force
