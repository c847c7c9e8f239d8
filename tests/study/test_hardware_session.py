"""`study run --driver hardware` and `study hardware check` against the firmware's
host build on a pseudo-terminal: a whole session, a unit unplugged mid-trial and
plugged in again, and a port with no one behind it."""

from __future__ import annotations

import json
import os
import threading
import time
import tty
from pathlib import Path

import pytest
from sqlalchemy import create_engine, select
from sqlalchemy.orm import Session

from db.models.audit import AuditEntry
from db.models.trial import Trial
from study.cli import main
from teleop_core.loop.host_unit import HostUnit
from tests.firmware_build import host_firmware
from tests.study.conftest import init_study, last_sample_s, one_error_line, stored_samples

__all__ = ["host_firmware"]  # the fixture, imported for the tests below

DESIGN = """\
name = "hardware session"
seed = 5
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 1
"""
TRIAL_S = 2.0
"""The trial limit in these tests (a hand on the host-built dial does not steer into the
LCCA, so each trial runs to the limit), s."""


@pytest.fixture
def short_trials(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("study.protocol.session.MAX_TRIAL_S", TRIAL_S)


def _trials(db: str) -> list[Trial]:
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine, expire_on_commit=False) as s:
        rows = list(s.scalars(select(Trial).order_by(Trial.id)))
        for row in rows:
            row.samples_stored = s.scalar(stored_samples(row.id))  # type: ignore[attr-defined]
            row.last_s = s.scalar(last_sample_s(row.id))  # type: ignore[attr-defined]
        s.expunge_all()
    engine.dispose()
    return rows


def _start(db: str, code: str, port: str) -> list[str]:
    return ["run", "--participant", code, "--driver", "hardware", "--port", port, "--db", db]


def test_a_whole_session_runs_on_the_host_built_dial(
    tmp_path: Path, host_firmware: Path, short_trials: None, patient_host: None
) -> None:
    db = init_study(tmp_path, DESIGN, ("novice",))
    with HostUnit(host_firmware, "dial", hand="0:0,0.5:0.3", joystick="0.2") as unit:
        assert main(_start(db, "P001", unit.port)) == 0
    trials = _trials(db)
    # both blocks, in the participant's counterbalanced order
    assert sorted(t.condition for t in trials) == ["HV", "VO"]
    assert {t.driver for t in trials} == {"hardware"}
    for t in trials:
        assert t.status == "completed"
        # every 100 Hz sample of the trial stored, and the unit named in its summary
        assert t.samples_stored == round(TRIAL_S * 100)  # type: ignore[attr-defined]
        assert t.summary["dial_firmware"] == "1.1.0-host"
        assert t.summary["dial_corrupt_lines"] == 0


def test_an_unplugged_unit_interrupts_the_trial_with_one_line_and_keeps_its_samples(
    tmp_path: Path, host_firmware: Path, short_trials: None, capsys: pytest.CaptureFixture[str]
) -> None:
    db = init_study(tmp_path, DESIGN, ("novice",))
    link = tmp_path / "dial-port"
    unit = HostUnit(host_firmware, "dial", hand="0.3", link=link).start()
    engine = create_engine(f"sqlite:///{db}")
    unplugged: list[float] = []

    def unplug_after_a_second_of_samples() -> None:
        # the trial's first committed second, then the cable pulled
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with Session(engine) as s:
                kept = s.scalar(select(last_sample_s(Trial.id).scalar_subquery()).limit(1))
            if kept is not None and kept >= 0.9:
                unplugged.append(kept)
                unit.unplug()
                return
            time.sleep(0.05)

    watcher = threading.Thread(target=unplug_after_a_second_of_samples)
    watcher.start()
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr("study.protocol.session.MAX_TRIAL_S", 30.0)
            line = one_error_line(capsys, _start(db, "P001", str(link)))
    finally:
        watcher.join()
        unit.stop()
        engine.dispose()
    assert unplugged, "the trial never stored a second of samples"
    assert "P001's lcca/" in line
    assert "interrupted" in line
    assert f"the unit on {link} is gone" in line
    assert "study run --participant P001" in line  # what to do next
    (trial,) = _trials(db)
    assert trial.status == "interrupted"
    # its samples up to the unplugging, not just to the last committed chunk
    assert trial.last_s >= unplugged[0]  # type: ignore[attr-defined]
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        audit = s.scalars(
            select(AuditEntry).where(AuditEntry.entity == "trial", AuditEntry.entity_id == trial.id)
        ).one()
    engine.dispose()
    assert audit.new_value == "interrupted"
    assert "is gone" in audit.reason

    # plugged in again (the same port's name): the next run repeats the trial
    with HostUnit(host_firmware, "dial", hand="0.3", link=link):
        assert main(_start(db, "P001", str(link))) == 0
    trials = _trials(db)
    assert [t.status for t in trials] == ["interrupted", "completed", "completed"]
    assert trials[1].attempt == 2
    assert trials[1].condition == trials[0].condition


def test_hardware_check_passes_on_the_host_built_units(
    tmp_path: Path, host_firmware: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "check.json"
    # the button pressed twice (0.2-0.4 s and 0.8-1.0 s), held at the check's end
    button = "0:0,0.2:0,0.201:1,0.4:1,0.401:0,0.8:0,0.801:1"
    with HostUnit(
        host_firmware, "dial", hand="0:0,1:0.5", joystick="0:0,1:1", button=button
    ) as unit:
        argv = ["hardware", "check", "--port", unit.port, "--role", "dial", "--seconds", "1.5"]
        assert main([*argv, "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "unit: dial, firmware 1.1.0-host (the firmware's host build" in printed
    assert printed.strip().endswith("check passed")
    result = json.loads(out.read_text())
    assert result["passed"]
    assert result["simulated"]
    assert result["round_trip_ms_median"] < 2.0
    assert result["line_rate_hz"] == pytest.approx(100, rel=0.05)
    # the hand turned the dial: whole AS5600 counts of 2 pi / 4096 rad
    assert result["angle_max_rad"] > 0.3
    assert result["angle_step_rad"] == pytest.approx(2 * 3.141592653589793 / 4096, rel=1e-3)
    assert result["joystick_max"] == pytest.approx(1.0)
    assert result["button_presses"] == 2
    assert "button pressed 2 time(s)" in printed
    with HostUnit(host_firmware, "drive") as unit:
        argv = ["hardware", "check", "--port", unit.port, "--role", "drive", "--seconds", "1"]
        assert main([*argv, "--spin", "4", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["role"] == "drive"
    assert result["speed_max_rad_s"] > 3.0


def test_hardware_check_fails_with_one_line_where_no_one_answers(
    capsys: pytest.CaptureFixture[str],
) -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        port = os.ttyname(slave)
        line = one_error_line(capsys, ["hardware", "check", "--port", port])
    finally:
        os.close(master)
        os.close(slave)
    assert f"--port {port}: no greeting from the unit on {port} within 2.0 s" in line
    assert "expected a unit running the study's firmware" in line


def test_hardware_check_refuses_a_unit_of_the_other_role(
    host_firmware: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with HostUnit(host_firmware, "drive") as unit:
        line = one_error_line(capsys, ["hardware", "check", "--port", unit.port, "--role", "dial"])
    assert "is a 'drive'; expected 'dial'" in line
