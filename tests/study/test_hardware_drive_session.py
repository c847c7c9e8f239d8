"""`study run --driver hardware --port DIAL --drive-port DRIVE`: real units on both
sides (the firmware's host build as dial and drive, each behind a pty) and the force
sensors of the design's `[sensors]` table (an emulated forces unit): a whole session
stored as measured, a drive unplugged or silent mid-trial, and the options refused."""

from __future__ import annotations

import csv
import json
import math
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import create_engine, select
from sqlalchemy.orm import Session

from db.models.audit import AuditEntry
from db.models.trial import Trial, TrialMeasure
from study.cli import main
from teleop_core.loop.follower_units import EmulatedForceUnit
from teleop_core.loop.host_unit import HostUnit
from tests.firmware_build import host_firmware
from tests.study.conftest import init_study, last_sample_s, one_error_line
from tests.study.test_hardware_session import TRIAL_S, _trials, short_trials

# the fixtures, imported for the tests below
__all__ = ["host_firmware", "short_trials"]

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
    tmp_path: Path, host_firmware: Path, short_trials: None, patient_host: None
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
        assert t.summary["drive_firmware"] == "1.1.0-host"
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
    patient_host: None,
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


PRESS_AFTER_S = 0.9
"""The button is pressed once a trial has stored this much of its samples, s."""


def _press_in_each_trial(db: str, dial: HostUnit, n: int) -> tuple[threading.Thread, list]:
    """A thread that presses the dial's button once in each of `n` trials, when the trial
    has stored `PRESS_AFTER_S` of samples; it records (trial id, stored up to, s)."""
    pressed: list[tuple[int, float]] = []

    def watch() -> None:
        engine = create_engine(f"sqlite:///{db}")
        deadline = time.monotonic() + 60
        try:
            while len(pressed) < n and time.monotonic() < deadline:
                with Session(engine) as s:
                    trial = s.scalar(select(Trial.id).order_by(Trial.id.desc()).limit(1))
                    kept = None if trial is None else s.scalar(last_sample_s(trial))
                if kept is not None and kept >= PRESS_AFTER_S and trial not in dict(pressed):
                    dial.press()
                    pressed.append((trial, kept))
                time.sleep(0.02)
        finally:
            engine.dispose()

    thread = threading.Thread(target=watch)
    thread.start()
    return thread, pressed


def test_the_dial_s_button_ends_a_physical_phantom_trial_as_reached(
    tmp_path: Path, host_firmware: Path, patient_host: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    limit_s = 4.0  # far past the press: only the button ends these trials
    monkeypatch.setattr("study.protocol.session.MAX_TRIAL_S", limit_s)
    with (
        EmulatedForceUnit(proximal, distal) as forces,
        HostUnit(host_firmware, "dial", hand="0.2") as dial,
        HostUnit(host_firmware, "drive") as drive,
    ):
        db = init_study(tmp_path, _design(forces.port), ("novice",))
        watcher, pressed = _press_in_each_trial(db, dial, 2)
        try:
            assert main(_start(db, dial.port, drive.port)) == 0
        finally:
            watcher.join()
    trials = _trials(db)
    assert [t.id for t in trials] == [trial for trial, _ in pressed]
    for t, (_, kept) in zip(trials, pressed, strict=True):
        assert t.status == "completed"
        assert t.success is True
        assert t.summary["end"] == "button"
        assert t.summary["phantom"] == "physical"
        # pressed after `kept` s of samples were stored, seen at a later 10 ms update
        assert kept <= t.completion_time_s < kept + 0.5
        # the samples end where the trial did
        assert t.last_s == pytest.approx(t.completion_time_s, abs=0.011)  # type: ignore[attr-defined]
        assert t.samples_stored == pytest.approx(t.completion_time_s * 100, abs=1.01)  # type: ignore[attr-defined]
    out = tmp_path / "analysis"
    assert main(["analyze", "--out", str(out), "--db", db]) == 0
    methods = (out / "methods.md").read_text()
    assert "a person judged when the tip reached the target" in methods
    assert "ended the trial as a success: 2 by the participant's button." in methods


LIMIT_S = 1.0
"""The time limit of the time-limit tests, s (short: nothing ends these trials earlier)."""


@pytest.mark.parametrize("button", ["0", "1"], ids=["never-pressed", "held-from-the-start"])
def test_a_physical_phantom_trial_that_reaches_the_time_limit_is_no_success(
    tmp_path: Path,
    host_firmware: Path,
    patient_host: None,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    button: str,
) -> None:
    monkeypatch.setattr("study.protocol.session.MAX_TRIAL_S", LIMIT_S)
    # a button held down since before the trial is no press: it must go up first
    with (
        EmulatedForceUnit(proximal) as forces,
        HostUnit(host_firmware, "dial", hand="0.2", button=button) as dial,
        HostUnit(host_firmware, "drive") as drive,
    ):
        db = init_study(tmp_path, _design(forces.port), ("novice",))
        capsys.readouterr()
        assert main(_start(db, dial.port, drive.port)) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "time limit" in line]
    assert len(said) == 2
    assert all("stored with success false" in line for line in said)
    trials = _trials(db)
    assert len(trials) == 2
    for t in trials:
        assert t.status == "completed"
        assert t.success is False
        assert t.summary["end"] == "time_limit"
        assert t.samples_stored == round(LIMIT_S * 100)  # type: ignore[attr-defined]
        assert t.completion_time_s == pytest.approx(LIMIT_S, abs=1e-9)  # the limit itself


def test_the_experimenter_s_keys_on_a_terminal_end_or_stop_a_physical_phantom_trial(
    tmp_path: Path,
    host_firmware: Path,
    patient_host: None,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setattr("study.protocol.session.MAX_TRIAL_S", 4.0)
    master, slave = os.openpty()  # the experimenter's terminal on stdin
    terminal = os.fdopen(slave, "r")
    monkeypatch.setattr("sys.stdin", terminal)
    typed: list[tuple[int, float]] = []

    def keys() -> None:
        """Enter in the first trial, `x` and a reason in the second, each once the
        trial has stored PRESS_AFTER_S of samples."""
        engine = create_engine(f"sqlite:///{db}")
        deadline = time.monotonic() + 60
        try:
            while len(typed) < 2 and time.monotonic() < deadline:
                with Session(engine) as s:
                    trial = s.scalar(select(Trial.id).order_by(Trial.id.desc()).limit(1))
                    kept = None if trial is None else s.scalar(last_sample_s(trial))
                if kept is not None and kept >= PRESS_AFTER_S and trial not in dict(typed):
                    os.write(master, b"\r" if not typed else b"x")
                    if typed:
                        time.sleep(0.3)  # the trial stands while the reason is typed
                        os.write(master, b"cable caught\n")
                    typed.append((trial, kept))
                time.sleep(0.02)
        finally:
            engine.dispose()

    with (
        EmulatedForceUnit(proximal) as forces,
        HostUnit(host_firmware, "dial", hand="0.2") as dial,
        HostUnit(host_firmware, "drive") as drive,
    ):
        db = init_study(tmp_path, _design(forces.port), ("novice",))
        capsys.readouterr()
        typist = threading.Thread(target=keys)
        typist.start()
        try:
            status = main(_start(db, dial.port, drive.port))
        finally:
            typist.join()
            terminal.close()
            os.close(master)
    err = capsys.readouterr().err
    assert status == 1
    assert "Enter when the tip has reached the target, x to stop the trial" in err
    assert "the trial stands; why stop it?" in err
    last = err.strip().splitlines()[-1]
    assert "stopped by the experimenter at the terminal: cable caught" in last
    assert "1 trial(s) completed and stored" in last
    first, second = _trials(db)
    assert (first.id, second.id) == tuple(trial for trial, _ in typed)
    assert (first.status, first.success, first.summary["end"]) == (
        "completed",
        True,
        "experimenter",
    )
    assert typed[0][1] <= first.completion_time_s < typed[0][1] + 0.5
    assert second.status == "interrupted"
    assert second.success is None
    assert second.summary is None
    assert second.last_s >= typed[1][1]  # type: ignore[attr-defined]  # its samples kept
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        reason = s.scalar(select(AuditEntry.reason).where(AuditEntry.entity_id == second.id))
    engine.dispose()
    assert reason == "stopped by the experimenter at the terminal: cable caught"
