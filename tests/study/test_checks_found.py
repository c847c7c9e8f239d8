"""Imports that enrol, the audit of enrolment, questionnaires and imports, `--out`
through a link, the lease's refusal and release, and stderr without a lone newline."""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
from contextlib import closing
from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.engine import make_engine
from db.models.audit import AuditEntry
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.exchange import TRIAL_COLUMNS

ONE_VO_TRIAL = ",".join(TRIAL_COLUMNS) + "\nP001,novice,lcca,VO,1,31.5,0.81,0.42,true\n"


def _init(tmp_path: Path) -> str:
    (tmp_path / "d.toml").write_text(TEMPLATE)
    db = str(tmp_path / "s.db")
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    return db


def _audit(db: str, entity: str) -> list[AuditEntry]:
    engine = make_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        rows = list(
            s.scalars(select(AuditEntry).where(AuditEntry.entity == entity).order_by(AuditEntry.id))
        )
        s.expunge_all()
    engine.dispose()
    return rows


def test_a_participant_created_by_an_import_gets_its_schedule(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = _init(tmp_path)
    (tmp_path / "one.csv").write_text(ONE_VO_TRIAL)
    assert main(["import", "--enrol-new", "--trials", str(tmp_path / "one.csv"), "--db", db]) == 0
    capsys.readouterr()
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    out, err = capsys.readouterr()
    # the template: 1 practice + 3 trials per block, VO then HV (the design's order);
    # VO trial 1 came from the file: VO practice + 2, HV practice + 3
    assert "P001: 7 trials completed and stored" in out
    assert not err.startswith("\n")  # no lone newline before the messages
    assert main(["schedule", "--json", "--db", db]) == 0
    blocks = json.loads(capsys.readouterr().out)["participants"][0]["blocks"]
    assert [(b["condition"], b["completed"], b["planned"]) for b in blocks] == [
        ("VO", 4, 4),
        ("HV", 4, 4),
    ]


def test_enrolment_and_imports_are_audited(tmp_path: Path) -> None:
    db = _init(tmp_path)
    add = ["participant", "add", "--group", "expert", "--site", "lab-b", "--actor", "EXP01"]
    assert main([*add, "--count", "2", "--db", db]) == 0
    enrolled = _audit(db, "participant")
    assert [json.loads(r.new_value)["code"] for r in enrolled] == ["P001", "P002"]
    assert {(json.loads(r.new_value)["site"], r.actor, r.field) for r in enrolled} == {
        ("lab-b", "EXP01", "enrolled")
    }
    csv = tmp_path / "one.csv"
    csv.write_text(ONE_VO_TRIAL.replace("P001,novice", "P003,novice"))
    assert (
        main(["import", "--enrol-new", "--trials", str(csv), "--actor", "EXP02", "--db", db]) == 0
    )
    (imported,) = _audit(db, "import")
    record = json.loads(imported.new_value)
    assert record == {
        "file": str(csv.resolve()),
        "rows": 1,
        "sha256": hashlib.sha256(csv.read_bytes()).hexdigest(),
    }
    assert (imported.field, imported.actor) == ("trials_csv", "EXP02")
    assert imported.at is not None
    # the participant the import created is enrolled in the log too, by the import
    new = _audit(db, "participant")[-1]
    assert json.loads(new.new_value) == {"group": "novice", "site": "imported", "by": "import"}


@pytest.mark.parametrize("through", ["link", "link/sub"])
def test_out_through_a_symbolic_link_is_refused(
    tmp_path: Path,
    through: str,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    db = _init(tmp_path)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere")
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["export", "--out", through, "--db", db]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "link is a symbolic link" in err[0], err
    assert list((tmp_path / "elsewhere").iterdir()) == []


def test_the_lease_refusal_says_when_a_session_is_taken_over(tmp_path: Path) -> None:
    from study.protocol.lease import SessionBusyError, acquire_lease

    db = _init(tmp_path)
    assert main(["participant", "add", "--group", "novice", "--db", db]) == 0
    engine = make_engine(f"sqlite:///{db}")
    try:
        held = acquire_lease(engine, 1, "P001")  # this process: alive on this host
        with pytest.raises(
            SessionBusyError,
            match="alive on this host; once it ends, a new session takes over at once",
        ):
            acquire_lease(engine, 1, "P001")
        with engine.begin() as conn:
            conn.exec_driver_sql("UPDATE session_leases SET host = 'lab-pc-2'")
        with pytest.raises(SessionBusyError, match="once its heartbeat is 30 s old"):
            acquire_lease(engine, 1, "P001")
        held.release()
    finally:
        engine.dispose()


def test_a_failed_release_does_not_replace_the_sessions_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from study.protocol.lease import LeaseHandle, hold_lease

    db = _init(tmp_path)
    assert main(["participant", "add", "--group", "novice", "--count", "2", "--db", db]) == 0
    engine = make_engine(f"sqlite:///{db}")

    def full(self: LeaseHandle) -> None:
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(LeaseHandle, "release", full)
    try:
        with pytest.raises(RuntimeError, match="the session's own error"):
            with hold_lease(engine, 1, "P001", heartbeat_s=0.05):
                raise RuntimeError("the session's own error")
        # without an error of its own, the release's error is the one reported
        with pytest.raises(sqlite3.OperationalError, match="disk is full"):
            with hold_lease(engine, 2, "P002", heartbeat_s=0.05):
                pass
    finally:
        engine.dispose()


def test_progress_bars_write_nothing_where_stderr_is_no_terminal(
    capfd: pytest.CaptureFixture[str],
) -> None:
    from study.commands.base import progress_bar

    with progress_bar() as bar:
        bar.advance(bar.add_task("x", total=2))
    assert capfd.readouterr().err == ""
    assert not os.isatty(2)


def test_killing_the_parent_of_jobs_2_prints_no_leaked_semaphore_warning(tmp_path: Path) -> None:
    import signal
    import subprocess
    import sys
    import time

    db = _init(tmp_path)
    assert main(["participant", "add", "--group", "novice", "--count", "3", "--db", db]) == 0
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    shm = set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()
    run = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; from study.cli import main; sys.exit(main())",
            "run",
            "--all",
            "--jobs",
            "2",
            "--pace",
            "1",
            "--db",
            db,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # kill once both workers run a trial
        with closing(sqlite3.connect(db)) as conn:
            running = "SELECT count(*) FROM trials WHERE status = 'running'"
            if conn.execute(running).fetchone()[0] >= 2:
                break
        time.sleep(0.2)
    run.send_signal(signal.SIGKILL)
    _, err = run.communicate(timeout=60)  # the workers and the tracker end too
    assert "leaked semaphore" not in err, err
    assert "Traceback" not in err, err
    if shm:  # the tracker still removed the pool's semaphores
        # other processes (a parallel test worker) may hold semaphores of their own for a
        # while; a leaked one never goes away, so wait for the transient ones to end
        deadline = time.monotonic() + 60
        while True:
            left = {n for n in set(os.listdir("/dev/shm")) - shm if n.startswith("sem.mp")}
            if not left or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        assert not left, left
