"""One session per participant: leases, takeover, `--jobs` workers.

Reproductions from the issue: `study run --participant P001 --pace 5 & study run
--participant P001` ran both sessions (slots completed twice); after `kill -9` of the
parent of `study run --all --jobs 2` its workers kept writing and the next run
completed slots twice.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path

import pytest
from sqlalchemy import Engine, func, select, update
from sqlalchemy.orm import Session

from db.base import utcnow
from db.engine import make_engine
from db.models.audit import AuditEntry
from db.models.lease import SessionLease
from db.models.trial import Trial
from study.cli import main
from study.protocol.actor import current_actor
from study.protocol.design import parse_design
from study.protocol.lease import (
    LEASE_TIMEOUT_S,
    LeaseLostError,
    SessionBusyError,
    acquire_lease,
    process_alive,
)
from study.protocol.roster import add_participant, create_study
from tests.study.conftest import assert_workers_end, init_study, samples_of_trial

DESIGN = """\
name = "lease test"
seed = 3
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 2
"""
CLI = [sys.executable, "-c", "from study.cli import main; raise SystemExit(main())"]


def _participant(engine: Engine) -> int:
    create_study(engine, parse_design(DESIGN), DESIGN)
    return add_participant(engine, "novice").id


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_live_holder_refuses_a_second_session_and_a_dead_one_is_taken_over(
    engine: Engine,
) -> None:
    pid = _participant(engine)
    first = acquire_lease(engine, pid, "P001", "EXP01")
    assert first.taken_over is None
    with pytest.raises(SessionBusyError, match=r"P001 already has a session running on .*EXP01"):
        acquire_lease(engine, pid, "P001")

    def holder(**values: object) -> None:
        with engine.begin() as conn:
            conn.execute(update(SessionLease).values(**values))

    # another lab machine, heartbeat 10 s old: alive
    holder(host="lab-pc-2", heartbeat_at=utcnow() - timedelta(seconds=10))
    with pytest.raises(SessionBusyError, match="lab-pc-2"):
        acquire_lease(engine, pid, "P001")
    # ... silent for longer than the timeout: dead, taken over
    holder(heartbeat_at=utcnow() - timedelta(seconds=LEASE_TIMEOUT_S + 5))
    second = acquire_lease(engine, pid, "P001")
    assert second.taken_over is not None
    assert "no heartbeat from lab-pc-2" in second.taken_over
    # the first holder learns it lost the lease at its next heartbeat
    assert not first.beat()
    with pytest.raises(LeaseLostError, match="P001"):
        first.check()
    assert second.beat()
    # a holder on this host whose process is gone is dead at once, however fresh its beat
    gone = _dead_pid()
    assert not process_alive(gone)
    assert process_alive(os.getpid())
    holder(host=socket.gethostname(), pid=gone, heartbeat_at=utcnow())
    third = acquire_lease(engine, pid, "P001")
    assert third.taken_over is not None
    assert f"process {gone}" in third.taken_over
    third.release()
    with Session(engine) as s:
        assert s.scalar(select(func.count()).select_from(SessionLease)) == 0


def _trials(url: str) -> list[tuple[int, int, str, int, int]]:
    """(id, slot, status, attempt, samples) of every trial."""
    engine = make_engine(url)
    with Session(engine) as s:
        rows = s.execute(
            select(
                Trial.id,
                Trial.participant_id * 100 + Trial.block_index * 10 + Trial.trial_index,
                Trial.status,
                Trial.attempt,
                samples_of_trial(),
            ).order_by(Trial.id)
        ).all()
    engine.dispose()
    return [tuple(r) for r in rows]


def _wait_for(url: str, ready: Callable[[list], bool], what: str, timeout_s: float = 90) -> list:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time.sleep(0.2)
        trials = _trials(url)
        if ready(trials):
            return trials
    pytest.fail(f"never saw {what}")


def _kill(proc: subprocess.Popen[bytes]) -> None:
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)


def test_second_run_of_a_participant_is_refused_then_takes_over_after_kill_9(
    db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "d.toml").write_text(DESIGN)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db_url]) == 0
    assert main(["participant", "add", "--group", "novice", "--db", db_url]) == 0
    first = subprocess.Popen(
        [*CLI, "run", "--participant", "P001", "--pace", "5", "--actor", "EXP01", "--db", db_url],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        before = _wait_for(
            db_url, lambda ts: any(t[2] == "running" and t[4] >= 100 for t in ts), "a running trial"
        )
        capsys.readouterr()
        assert main(["run", "--participant", "P001", "--db", db_url]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        assert "P001 already has a session running" in err[0], err
        assert "EXP01" in err[0]
        # the refused session wrote nothing: no new trial, the running one untouched
        now = _trials(db_url)
        assert [t[:4] for t in now] == [t[:4] for t in before]
        _kill(first)
    finally:
        if first.poll() is None:
            first.kill()
    killed = next(t for t in _trials(db_url) if t[2] == "running")
    assert main(["run", "--participant", "P001", "--db", db_url]) == 0
    after = _trials(db_url)
    completed = [t[1] for t in after if t[2] == "completed"]
    assert sorted(completed) == sorted(set(completed))
    assert len(completed) == 2
    engine = make_engine(db_url)
    with Session(engine) as s:
        audit = s.scalars(
            select(AuditEntry).where(
                AuditEntry.entity == "trial", AuditEntry.entity_id == killed[0]
            )
        ).one()
    engine.dispose()
    assert audit.new_value == "interrupted"
    assert f"process {first.pid}" in audit.reason
    assert "gone" in audit.reason
    assert audit.actor == current_actor()  # the operating-system user and host


def _children(pid: int) -> list[int]:
    """Worker processes of `pid` (multiprocessing's spawned children)."""
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        if int(stat.rpartition(")")[2].split()[1]) == pid and b"spawn_main" in cmdline:
            out.append(int(entry.name))
    return out


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="finds the workers through /proc")
def test_jobs_workers_end_with_their_parent_and_no_slot_completes_twice(
    tmp_path: Path,
) -> None:
    db = init_study(tmp_path, DESIGN, groups=("novice", "novice"))
    url = f"sqlite:///{db}"
    parent = subprocess.Popen(
        [*CLI, "run", "--all", "--jobs", "2", "--pace", "5", "--db", db],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        _wait_for(
            url,
            lambda ts: sum(t[2] == "running" and t[4] >= 100 for t in ts) == 2,
            "both workers mid-trial",
        )
        workers = _children(parent.pid)
        assert len(workers) == 2
        _kill(parent)
    finally:
        if parent.poll() is None:
            parent.kill()
    assert_workers_end(workers, 30)
    stopped = _trials(url)
    # each worker marked its own trial interrupted on the way out, and writes no more
    assert not [t for t in stopped if t[2] == "running"]
    time.sleep(1.0)
    assert _trials(url) == stopped
    assert main(["run", "--all", "--db", db]) == 0
    final = _trials(url)
    completed = [t[1] for t in final if t[2] == "completed"]
    assert len(completed) == 4
    assert len(set(completed)) == 4
    engine = make_engine(url)
    with Session(engine) as s:
        reasons = s.scalars(select(AuditEntry.reason).where(AuditEntry.new_value == "interrupted"))
        assert set(reasons) == {"the session stopped because its parent `study run` process ended"}
    engine.dispose()
