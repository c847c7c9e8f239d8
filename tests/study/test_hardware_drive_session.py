"""`study run --driver hardware --port DIAL --drive-port DRIVE`: real units on both
sides (the firmware's host build as dial and drive, each behind a pty) and the force
sensors of the design's `[sensors]` table (an emulated forces unit): a whole session
stored as measured, a drive unplugged or silent mid-trial, and the options refused."""

from __future__ import annotations

import csv
import json
import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import create_engine, select
from sqlalchemy.orm import Session

from db.models.trial import Trial, TrialMeasure
from study.cli import main
from teleop_core.loop.follower_units import EmulatedForceUnit
from teleop_core.loop.host_unit import HostUnit
from tests.firmware_build import host_firmware
from tests.study.conftest import init_study, last_sample_s, one_error_line
from tests.study.test_hardware_session import TRIAL_S, _trials, short_trials

__all__ = ["host_firmware", "short_trials"]  # the fixtures, imported for the tests below

DESIGN = """\
name = "real units"
seed = 5
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 1
"""


def _design(forces_port: str) -> str:
    return f'{DESIGN}[sensors]\nsource = "serial"\nport = "{forces_port}"\n'


def proximal(t_s: float) -> float:
    return 0.2 + 0.1 * t_s


def distal(t_s: float) -> float:
    return 0.3 if 0.5 <= t_s < 1.0 else 0.0


def _start(db: str, dial: str, drive: str) -> list[str]:
    return [
        "run",
        "--participant",
        "P001",
        "--driver",
        "hardware",
        "--port",
        dial,
        "--drive-port",
        drive,
        "--db",
        db,
    ]


def _samples(tmp_path: Path, db: str) -> list[dict[str, str]]:
    out = tmp_path / "export"
    assert main(["export", "--out", str(out), "--samples", "--db", db]) == 0
    with (out / "trials.csv").open() as f:
        trials = list(csv.DictReader(f))
    assert {t["data_source"] for t in trials} == {"measured"}
    assert {t["driver"] for t in trials} == {"hardware"}
    with (out / "samples.csv").open() as f:
        return list(csv.DictReader(f))


def test_a_whole_session_on_real_units_stores_every_trial_as_measured(
    tmp_path: Path, host_firmware: Path, short_trials: None
) -> None:
    with (
        EmulatedForceUnit(proximal, distal) as forces,
        HostUnit(host_firmware, "dial", hand="0:0,0.5:0.3", joystick="0.2") as dial,
        HostUnit(host_firmware, "drive") as drive,
    ):
        db = init_study(tmp_path, _design(forces.port), ("novice",))
        assert main(_start(db, dial.port, drive.port)) == 0
    trials = _trials(db)
    assert sorted(t.condition for t in trials) == ["HV", "VO"]
    n = round(TRIAL_S * 100)
    for t in trials:
        assert t.status == "completed"
        assert t.samples_stored == n  # type: ignore[attr-defined]
        assert t.summary["forces"] == "measured"
        assert t.summary["phantom"] == "physical"
        # the estimator was fed one drive state line per stored sample
        assert t.summary["drive_state_lines"] == n
        assert t.summary["drive_firmware"] == "1.0.0-host"
        assert t.summary["drive_corrupt_lines"] == 0
        assert t.summary["force_sensor_firmware"] == "emu-1"
        # the peak forces are the sensors' (the unit's clock restarts at each HELLO):
        # proximal 0.2 + 0.1 t at the last sample, distal the 0.3 N step
        assert t.summary["peak_proximal_reference_force_n"] == pytest.approx(
            proximal((n - 1) * 0.01), abs=1e-4
        )
    samples = _samples(tmp_path, db)
    assert len(samples) == 2 * n
    first = [s for s in samples if s["trial"] == samples[0]["trial"]][:n]
    reference = np.array([float(s["reference_force_n"]) for s in first])
    # no simulated "true" force: the stored reference is the sensor's, sample by sample
    assert np.allclose(reference, [proximal(k * 0.01) for k in range(n)], atol=1e-4)
    assert max(float(s["distal_force_n"]) for s in first) == pytest.approx(0.3)
    assert all(s["tip_x_m"] in ("", "nan", "NaN") for s in first)
    assert any(abs(float(s["proximal_force_n"])) > 0 for s in first)  # the estimate
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        peaks = s.execute(
            select(TrialMeasure.value).where(TrialMeasure.name == "peak_distal_force_n")
        ).scalars()
        assert [round(v, 4) for v in peaks] == [0.3, 0.3]
    engine.dispose()
    # the analysis calls them measured, forces and all
    out = tmp_path / "analysis"
    assert main(["analyze", "--out", str(out), "--db", db]) == 0
    source = json.loads((out / "analysis.json").read_text())["data_source"]
    assert (source["label"], source["note"]) == ("hardware", "")
    methods = (out / "methods.md").read_text()
    assert "The forces of 2 of them were measured, with the real drive in a physical" in methods
    assert "simulated" not in methods.lower()
    with (out / "descriptives.csv").open() as f:
        assert {r["data_source"] for r in csv.DictReader(f)} == {"hardware"}


@pytest.mark.parametrize("failure", ["unplug", "freeze"])
def test_a_drive_that_goes_away_mid_trial_interrupts_it_with_one_line(
    tmp_path: Path,
    host_firmware: Path,
    capsys: pytest.CaptureFixture[str],
    failure: str,
) -> None:
    link = tmp_path / "drive-port"
    with (
        EmulatedForceUnit(proximal) as forces,
        HostUnit(host_firmware, "dial", hand="0.3") as dial,
        HostUnit(host_firmware, "drive", link=link) as drive,
    ):
        db = init_study(tmp_path, _design(forces.port), ("novice",))
        engine = create_engine(f"sqlite:///{db}")
        failed: list[float] = []

        def fail_after_a_second_of_samples() -> None:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                with Session(engine) as s:
                    kept = s.scalar(select(last_sample_s(Trial.id).scalar_subquery()).limit(1))
                if kept is not None and kept >= 0.9:
                    failed.append(kept)
                    drive.unplug() if failure == "unplug" else drive.freeze()
                    return
                time.sleep(0.05)

        watcher = threading.Thread(target=fail_after_a_second_of_samples)
        watcher.start()
        try:
            with pytest.MonkeyPatch.context() as mp:
                mp.setattr("study.protocol.session.MAX_TRIAL_S", 30.0)
                line = one_error_line(capsys, _start(db, dial.port, str(link)))
        finally:
            watcher.join()
            if failure == "freeze":
                drive.thaw()
            engine.dispose()
    assert failed, "the trial never stored a second of samples"
    assert "P001's lcca/" in line
    assert "interrupted" in line
    said = "is gone" if failure == "unplug" else "no answer from the unit"
    assert f"the unit on {link}" in line
    assert said in line
    (trial,) = _trials(db)
    assert trial.status == "interrupted"
    assert trial.last_s >= failed[0]  # type: ignore[attr-defined]
    assert not math.isnan(trial.last_s)  # type: ignore[attr-defined]


def test_drive_port_options_are_refused_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = init_study(tmp_path, DESIGN, ("novice",))
    argv = ["run", "--participant", "P001", "--drive-port", "/dev/ttyUSB1", "--db", db]
    line = one_error_line(capsys, argv)
    assert "--drive-port with --driver simulated; expected --driver hardware" in line
    line = one_error_line(capsys, _start(db, "/dev/ttyUSB0", "/dev/ttyUSB1"))
    assert "--drive-port /dev/ttyUSB1: the study's design names no force sensors" in line
    assert "expected a [sensors] table" in line
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        assert s.scalars(select(Trial)).all() == []  # nothing written
    engine.dispose()


def test_a_drive_port_where_no_one_answers_is_refused_before_a_trial(
    tmp_path: Path, host_firmware: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with EmulatedForceUnit() as forces, HostUnit(host_firmware, "dial") as dial:
        db = init_study(tmp_path, _design(forces.port), ("novice",))
        line = one_error_line(capsys, _start(db, dial.port, str(tmp_path / "nothing")))
    assert f"--drive-port {tmp_path / 'nothing'}: cannot open serial port" in line
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        assert s.scalars(select(Trial)).all() == []
    engine.dispose()
