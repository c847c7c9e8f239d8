"""A `study run` that is killed leaves no trial `running` for the readers: SIGTERM and
SIGHUP end the session with its trial interrupted (a paced simulated session, and one on
the firmware's host-built dial), and after a `kill -9` the readers show the dead
session's trial as interrupted without writing, while a live session's stays running."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from datetime import timedelta
from pathlib import Path

import pytest
from sqlalchemy import create_engine, func, select, update
from sqlalchemy.orm import Session

from db.base import utcnow
from db.models.audit import AuditEntry
from db.models.lease import SessionLease
from db.models.trial import Trial
from study.cli import main
from study.protocol.stop_signals import stop_on_signals
from teleop_core.loop.host_unit import HostUnit
from tests.firmware_build import host_firmware
from tests.study.conftest import init_study, stored_samples

__all__ = ["host_firmware"]  # the fixture, imported for the test below

DESIGN = """\
name = "stopped sessions"
seed = 5
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 2
"""
STUDY = [sys.executable, "-c", "from study.cli import main; raise SystemExit(main())"]


def _trials(db: str) -> list[tuple[int, str, int]]:
    """(id, status, samples stored) of every trial row."""
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        rows = [(t.id, t.status, s.scalar(stored_samples(t.id))) for t in s.scalars(select(Trial))]
    engine.dispose()
    return rows


def _start_and_signal(db: str, argv: list[str], signum: int) -> tuple[int, str, int]:
    """Run `study ARGV` until its trial has stored a second of samples, send it `signum`;
    its exit status, its stderr and the samples stored when the signal went."""
    proc = subprocess.Popen(
        [*STUDY, *argv, "--db", db],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 90
        seen = 0
        while time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
            running = [n for _, status, n in _trials(db) if status == "running"]
            if running and running[0] >= 100:  # a second at 100 Hz, committed
                seen = running[0]
                break
        else:
            pytest.fail("the session never stored a second of its trial")
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, err, seen


def _assert_interrupted_by(db: str, seen: int, name: str) -> None:
    (trial,) = _trials(db)
    assert trial[1] == "interrupted"
    assert trial[2] >= seen  # its samples to the signal, at least those seen before it
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        audit = s.scalars(
            select(AuditEntry).where(AuditEntry.entity == "trial", AuditEntry.entity_id == trial[0])
        ).one()
        leases = s.scalar(select(func.count()).select_from(SessionLease))
    engine.dispose()
    assert (audit.old_value, audit.new_value) == ("running", "interrupted")
    assert audit.reason == f"the session stopped on {name}: its `study run` process was ended"
    assert leases == 0  # released: the next session starts without a takeover


def test_the_stop_event_names_its_signal_and_the_handlers_come_back() -> None:
    before = signal.getsignal(signal.SIGHUP)
    with stop_on_signals() as stop:
        assert not stop.is_set()
        os.kill(os.getpid(), signal.SIGHUP)
        deadline = time.monotonic() + 5
        while not stop.is_set() and time.monotonic() < deadline:
            time.sleep(0.01)  # Python runs the handler between bytecodes
        assert stop.is_set()
        assert (stop.signum, stop.exit_status) == (signal.SIGHUP, 128 + 1)
        # a second SIGHUP would end the process at once
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_DFL
        assert signal.getsignal(signal.SIGTERM) == stop.on_signal
    assert signal.getsignal(signal.SIGHUP) is before


def test_sigterm_ends_a_session_with_its_trial_interrupted_and_one_line(tmp_path: Path) -> None:
    db = init_study(tmp_path, DESIGN, ("novice",))
    argv = ["run", "--participant", "P001", "--pace", "1"]
    status, err, seen = _start_and_signal(db, argv, signal.SIGTERM)
    assert status == 128 + signal.SIGTERM
    lines = err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("study run: P001: the session stopped on SIGTERM")
    assert "0 trial(s) completed and stored" in lines[0]
    assert "P001's lcca/" in lines[0]
    assert "trial 1 marked interrupted" in lines[0]
    _assert_interrupted_by(db, seen, "SIGTERM")


def test_sighup_ends_a_session_on_the_host_built_dial(tmp_path: Path, host_firmware: Path) -> None:
    db = init_study(tmp_path, DESIGN, ("novice",))
    with HostUnit(host_firmware, "dial", hand="0.3") as unit:
        argv = ["run", "--participant", "P001", "--driver", "hardware", "--port", unit.port]
        status, err, seen = _start_and_signal(db, argv, signal.SIGHUP)
        # the unit is left with its command zeroed and its port free: it greets again
        check = ["hardware", "check", "--port", unit.port, "--seconds", "0.5"]
        assert main(check) == 0
    assert status == 128 + signal.SIGHUP
    assert "the session stopped on SIGHUP" in err
    _assert_interrupted_by(db, seen, "SIGHUP")


def _listed(db: str, capsys: pytest.CaptureFixture[str]) -> tuple[str, list[int]]:
    """`study trial list P001`'s line and `study schedule`'s interrupted counts of P001."""
    capsys.readouterr()
    assert main(["trial", "list", "P001", "--db", db]) == 0
    (line,) = capsys.readouterr().out.strip().splitlines()
    assert main(["schedule", "--json", "--db", db]) == 0
    plan = json.loads(capsys.readouterr().out)
    p001 = next(p for p in plan["participants"] if p["code"] == "P001")
    return line, [b["interrupted"] for b in p001["blocks"]]


def test_after_kill_9_the_readers_show_the_trial_interrupted_and_write_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = init_study(tmp_path, DESIGN, ("novice",))
    status, _, _ = _start_and_signal(db, ["run", "--participant", "P001", "--pace", "1"], 9)
    assert status == -signal.SIGKILL
    line, interrupted = _listed(db, capsys)
    assert ": interrupted (its session is gone: its process " in line
    assert "the participant's next `study run` records it" in line
    assert sorted(interrupted) == [0, 1]  # the first block's trial
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        # nothing written: the row still says running, no audit entry, the lease left
        assert s.scalar(select(Trial.status)) == "running"
        trial_audit = select(func.count()).where(AuditEntry.entity == "trial")
        assert s.scalar(trial_audit) == 0
        assert s.scalar(select(func.count()).select_from(SessionLease)) == 1

    def lease(**values: object) -> None:
        with engine.begin() as conn:
            conn.execute(update(SessionLease).values(**values))

    # a live holder on this host (this process), or on another machine with a fresh
    # heartbeat: the trial is running
    lease(pid=os.getpid(), host=socket.gethostname(), heartbeat_at=utcnow())
    line, interrupted = _listed(db, capsys)
    assert line.endswith(": running")
    assert interrupted == [0, 0]
    lease(pid=1, host="another-lab-pc", heartbeat_at=utcnow() - timedelta(seconds=5))
    line, _ = _listed(db, capsys)
    assert line.endswith(": running")
    # that machine's heartbeat past the lease timeout (30 s): gone
    lease(heartbeat_at=utcnow() - timedelta(seconds=45))
    line, interrupted = _listed(db, capsys)
    assert "interrupted (its session is gone: no heartbeat from another-lab-pc" in line
    assert sorted(interrupted) == [0, 1]
    # no lease at all (a session that ended without marking its trial)
    with engine.begin() as conn:
        conn.execute(SessionLease.__table__.delete())
    line, _ = _listed(db, capsys)
    assert "interrupted (its session ended without finishing it;" in line
    engine.dispose()
