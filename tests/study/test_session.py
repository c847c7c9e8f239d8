"""`study run`: sessions stream to the database and survive kill -9."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sqlalchemy import create_engine, select
from sqlalchemy.orm import Session

from db.models.audit import AuditEntry
from db.models.trial import Trial
from study.cli import main
from tests.study.conftest import last_sample_s, stored_samples

DESIGN = """\
name = "session test"
seed = 3
trials_per_condition = 2
practice_trials = 0
[groups]
novice = 2
"""


def _study(tmp_path: Path) -> str:
    db = str(tmp_path / "s.db")
    (tmp_path / "d.toml").write_text(DESIGN)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    assert main(["participant", "add", "--group", "novice", "--db", db]) == 0
    return db


def _trials(db: str) -> list[tuple[int, int, str, int, int]]:
    """(id, slot, status, attempt, samples) for every trial."""
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        rows = s.execute(
            select(
                Trial.id, Trial.block_index * 10 + Trial.trial_index, Trial.status, Trial.attempt
            ).order_by(Trial.id)
        ).all()
        out = [(*r, s.scalar(stored_samples(r[0]))) for r in rows]
    engine.dispose()
    return out


def test_a_session_stores_every_trial_with_its_samples(tmp_path: Path) -> None:
    db = _study(tmp_path)
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    trials = _trials(db)
    assert [t[2] for t in trials] == ["completed"] * 4
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        for trial in s.scalars(select(Trial)):
            # one row per 100 Hz sample over the trial
            n = s.scalar(stored_samples(trial.id))
            assert n == round(trial.completion_time_s * 100)
            assert trial.summary["samples"] == n
    engine.dispose()
    # nothing left to do: a second run completes nothing new
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    assert len(_trials(db)) == 4


def test_kill_9_mid_trial_keeps_completed_trials_and_repeats_the_running_one(
    tmp_path: Path,
) -> None:
    db = _study(tmp_path)
    cmd = [sys.executable, "-c", "from study.cli import main; raise SystemExit(main())"]
    proc = subprocess.Popen(
        [*cmd, "run", "--participant", "P001", "--pace", "15", "--db", db],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            time.sleep(0.2)
            trials = _trials(db) if Path(db).exists() else []
            done = [t for t in trials if t[2] == "completed"]
            running = [t for t in trials if t[2] == "running" and t[4] >= 200]
            if done and running:
                break
        else:
            pytest.fail("the session never had a completed and a running trial")
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    before = _trials(db)
    killed = next(t for t in before if t[2] == "running")
    # the completed trials are intact; the running one kept its committed chunks
    assert killed[4] > 0
    assert killed[4] % 100 == 0
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    after = {t[0]: t for t in _trials(db)}
    for t in before:
        if t[2] == "completed":
            assert after[t[0]] == t
    assert after[killed[0]][2] == "interrupted"
    assert after[killed[0]][4] == killed[4]
    repeats = [t for t in after.values() if t[1] == killed[1] and t[0] != killed[0]]
    assert len(repeats) == 1
    assert repeats[0][2] == "completed"
    assert repeats[0][3] == 2
    assert sorted({t[1] for t in after.values() if t[2] == "completed"}) == [0, 1, 10, 11]
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        audit = s.scalars(select(AuditEntry).where(AuditEntry.entity_id == killed[0])).one()
        assert (audit.old_value, audit.new_value) == ("running", "interrupted")
    engine.dispose()


def test_unknown_participant_and_keyboard_driver_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = _study(tmp_path)
    capsys.readouterr()
    assert main(["run", "--participant", "P404", "--db", db]) == 2
    assert main(["run", "--participant", "P001", "--driver", "keyboard", "--db", db]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2
    assert "P404" in err[0]
    assert "study tui" in err[1]


def test_run_all_runs_every_participant_in_two_processes(tmp_path: Path) -> None:
    db = _study(tmp_path)
    assert main(["participant", "add", "--group", "novice", "--db", db]) == 0
    assert main(["run", "--all", "--jobs", "2", "--db", db]) == 0
    trials = _trials(db)
    assert len(trials) == 8
    assert all(t[2] == "completed" for t in trials)
    assert main(["run", "--all", "--participant", "P001", "--db", db]) == 2


def test_workers_started_before_their_database_exists_run_its_sessions(tmp_path: Path) -> None:
    """`study demo`'s order: the workers start, then the study is created; a worker opens
    the database at its first session, and takes other work after the sessions."""
    from study.protocol.parallel import start_workers

    db = str(tmp_path / "s.db")
    with start_workers(db, 2, durable=False) as workers:
        (tmp_path / "d.toml").write_text(DESIGN)
        assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
        for _ in range(2):
            assert main(["participant", "add", "--group", "novice", "--db", db]) == 0
        done = sorted(workers.run(["P001", "P002"]))
        assert workers.submit(divmod, 7, 2).result() == (3, 1)
    assert done == [("P001", 4), ("P002", 4)]
    assert [t[2] for t in _trials(db)] == ["completed"] * 8


def test_one_job_runs_the_work_here_and_hands_back_its_error(tmp_path: Path) -> None:
    from study.protocol.parallel import Workers

    with Workers(str(tmp_path / "not_yet.db"), 1) as workers:
        assert workers.submit(divmod, 7, 2).result() == (3, 1)
        with pytest.raises(ZeroDivisionError):
            workers.submit(divmod, 1, 0).result()


_DIE_AT = """
import os, signal, sys
from db.migrate import open_database
from study.protocol.default_estimator import load_estimator
from study.tasks.lcca.simulated_participant import SimulatedParticipant
from study.protocol.session import participant_traits, run_session
from study.protocol.session_settings import SessionSettings
from teleop_core.phantom.lcca import LccaPhantom

die_at_s = float(sys.argv[2])
engine = open_database(sys.argv[1], create=False)
phantom = LccaPhantom()


class DiesAt(SimulatedParticipant):
    def act(self, view):
        if view.t_s >= die_at_s:  # the loop has made every sample up to here
            os.kill(os.getpid(), signal.SIGKILL)
        return super().act(view)


traits = participant_traits(3, "P001", "novice")
settings = SessionSettings(
    "simulated", load_estimator(), make_driver=lambda: DiesAt(traits, phantom, 180.0)
)
run_session(engine, "P001", settings)
"""


def test_an_unpaced_session_killed_at_any_time_loses_at_most_one_second(tmp_path: Path) -> None:
    """Unpaced runs hand the writer steps of up to a chunk (1 s); a
    kill lost 1.5 s when a chunk was committed only as the next step arrived."""
    db = _study(tmp_path)
    # kill times drawn once (numpy.random.default_rng(18).uniform(1, 8, 2).round(2))
    for die_at_s in (3.8, 6.02):
        proc = subprocess.run(
            [sys.executable, "-c", _DIE_AT, f"sqlite:///{db}", str(die_at_s)],
            capture_output=True,
            timeout=120,
        )
        assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()
        engine = create_engine(f"sqlite:///{db}")
        with Session(engine) as s:
            trial = s.scalars(select(Trial).where(Trial.status == "running")).one()
            kept_s = s.scalar(last_sample_s(trial.id))
        engine.dispose()
        # samples up to die_at_s were made; the last kept one is at most 1 s before it
        assert die_at_s - 1.0 <= kept_s + 0.01 <= die_at_s + 0.01
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    assert sorted(t[2] for t in _trials(db)) == ["completed"] * 4 + ["interrupted"] * 2


def test_a_full_disk_mid_trial_is_one_line_saying_what_was_kept(tmp_path: Path) -> None:
    """A full disk gave 2-4 chained tracebacks. SQLite's page limit
    makes the database full for real (SQLITE_FULL) a few pages into the first trial."""
    from sqlalchemy import event

    from db.migrate import open_database
    from study.protocol.default_estimator import load_estimator
    from study.protocol.session import SessionStorageError, run_session
    from study.protocol.session_settings import SessionSettings

    db = _study(tmp_path)
    engine = open_database(db, create=False)
    with engine.connect() as conn:
        pages = conn.exec_driver_sql("PRAGMA page_count").scalar()

    @event.listens_for(engine, "connect")
    def _limit(dbapi_connection, _record) -> None:  # type: ignore[no-untyped-def]
        dbapi_connection.execute(f"PRAGMA max_page_count = {pages + 12}")

    engine.dispose()  # new connections get the limit
    try:
        with pytest.raises(SessionStorageError) as caught:
            run_session(engine, "P001", SessionSettings("simulated", load_estimator()))
    finally:
        engine.dispose()
    message = str(caught.value)
    assert "\n" not in message
    assert "full" in message
    trials = _trials(db)
    assert [t[2] for t in trials] == ["running"]  # kept as it was, for the next run
    kept_s = float(message.split("samples up to t = ")[1].split(" s")[0])
    assert abs(kept_s * 100 - trials[0][4]) <= 1  # the message matches what is stored (100 Hz)
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    assert sorted(t[2] for t in _trials(db)) == ["completed"] * 4 + ["interrupted"]


def test_a_full_disk_after_a_completed_trial_is_one_line_and_keeps_that_trial(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """`study run` as the lab runs it: the database fills up in the second trial (its
    sample writer's 6th commit raises what SQLite raises then). One line, exit 2, saying
    what was kept up to which trial time; the completed trial is intact."""
    import sqlite3

    from db import samples as sample_store

    db = _study(tmp_path)
    real = sample_store._write_chunk
    commits: list[int] = []  # samples of each commit that went through
    per_trial: dict[int, int] = {}  # commits per trial, in the order the trials ran

    def fills_up(conn, row):  # type: ignore[no-untyped-def]
        n = per_trial.setdefault(row["trial_id"], 0)
        if len(per_trial) == 2 and n >= 5:
            raise sqlite3.OperationalError("database or disk is full")
        real(conn, row)
        per_trial[row["trial_id"]] = n + 1
        commits.append(row["n_samples"])

    monkeypatch.setattr(sample_store, "_write_chunk", fills_up)
    capsys.readouterr()
    assert main(["run", "--participant", "P001", "--db", db]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    trials = _trials(db)
    assert [t[2] for t in trials] == ["completed", "running"]
    assert trials[0][4] + trials[1][4] == sum(commits)  # every commit before the failure
    kept_s = float(err[0].split("samples up to t = ")[1].split(" s")[0])
    assert abs(kept_s * 100 + 1 - trials[1][4]) <= 1  # the line matches what is stored
    assert "database or disk is full" in err[0]
    assert "kept 1 trial(s) of P001 completed" in err[0]
    monkeypatch.undo()
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    after = _trials(db)
    assert after[0] == trials[0]  # the completed trial untouched
    assert sorted(t[2] for t in after) == ["completed"] * 4 + ["interrupted"]


def test_a_lock_taken_as_a_watched_trial_ends_is_waited_out_and_the_trial_completes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Another program takes the write lock between the trial's last samples and its
    `completed` write, and keeps it longer than the busy timeout. A watched session
    (`wait_out_storage`, as the terminal app runs it), which keeps its samples through
    such a lock, waits this one out too, saying so, and completes the trial rather than
    leave it `running` for the next session to repeat."""
    import sqlite3
    from contextlib import closing

    from db.migrate import open_database
    from study.protocol.default_estimator import load_estimator
    from study.protocol.observer import SessionObserver
    from study.protocol.session import run_session
    from study.protocol.session_settings import SessionSettings
    from study.protocol.tasks import get_task

    db = _study(tmp_path)
    engine = open_database(f"sqlite:///{db}?timeout=0.2", create=False)
    with closing(sqlite3.connect(db, isolation_level=None)) as holder:
        (task,) = {name for (name,) in holder.execute("SELECT task FROM schedule_blocks")}
        task_class = type(get_task(task))
        measure = task_class.completion_time_s

        def lock_then_measure(self, samples):  # type: ignore[no-untyped-def]
            # after the sample writer's last commit, before the trial's final write
            if not holder.in_transaction:
                holder.execute("BEGIN IMMEDIATE")
            return measure(self, samples)

        monkeypatch.setattr(task_class, "completion_time_s", lock_then_measure)
        waits: list[tuple[float | None, int]] = []

        class Waits(SessionObserver):
            def storage_wait(self, waited_s: float | None, held: int) -> None:
                waits.append((waited_s, held))
                # the other program is done once the runner has said it waits for it
                if waited_s is not None and len(waits) == 3:
                    holder.execute("ROLLBACK")

        try:
            settings = SessionSettings(
                "simulated", load_estimator(), max_trials=1, wait_out_storage=True
            )
            ids = run_session(engine, "P001", settings, Waits())
        finally:
            if holder.in_transaction:
                holder.execute("ROLLBACK")
            engine.dispose()
    assert len(ids) == 1
    assert [t[2] for t in _trials(db)] == ["completed"]
    assert [w for w, _ in waits[:3]] == sorted(w for w, _ in waits[:3])
    assert all(w is not None and held == 0 for w, held in waits[:3])
    assert waits[3:] == [(None, 0)]  # the wait ended, said once


@pytest.mark.parametrize(
    ("values", "line"),
    [
        ({"pace": 0.0}, "pace 0.0; expected a finite number > 0 (times real time)"),
        ({"pace": -2.0}, "pace -2.0; expected a finite number > 0 (times real time)"),
        ({"pace": float("nan")}, "pace nan; expected a finite number > 0 (times real time)"),
        ({"pace": float("inf")}, "pace inf; expected a finite number > 0 (times real time)"),
        ({"max_trials": -1}, "max_trials -1; expected a whole number >= 0"),
    ],
)
def test_session_settings_refuse_a_value_out_of_range_as_they_are_made(
    values: dict[str, float], line: str
) -> None:
    """The settings check each value once, where it enters: before any database is
    opened, with one line naming the value and what was expected."""
    from study.errors import StudyInputError
    from study.protocol.session_settings import SessionSettings

    with pytest.raises(StudyInputError) as caught:
        SessionSettings("simulated", None, **values)  # type: ignore[arg-type]
    assert str(caught.value) == line


def test_study_run_reads_the_design_once_for_the_session(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`study run` reads the study's design once (its `[lsl]` and `[sensors]` tables,
    the session's gains and time limit) and hands it on; it read it twice before the
    first trial, once for the streams and once in the runner."""
    from study.protocol.design import StudyDesign

    db = _study(tmp_path)
    reads: list[str] = []
    read = StudyDesign.from_dict.__func__  # type: ignore[attr-defined]

    def counted(cls, data):  # type: ignore[no-untyped-def]
        reads.append(data["name"])
        return read(cls, data)

    monkeypatch.setattr(StudyDesign, "from_dict", classmethod(counted))
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    assert reads == ["session test"]
    assert [t[2] for t in _trials(db)] == ["completed"] * 4


def test_study_run_all_reads_the_design_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`study run --all` reads the design once for the notice on its `[lsl]` table, the
    roster and every participant's session (with one job the sessions run in this
    process, so every read is counted); it read it once more for the notice, once for
    the roster and once per session."""
    from study.protocol.design import StudyDesign

    db = _study(tmp_path)
    assert main(["participant", "add", "--group", "novice", "--db", db]) == 0
    reads: list[str] = []
    read = StudyDesign.from_dict.__func__  # type: ignore[attr-defined]

    def counted(cls, data):  # type: ignore[no-untyped-def]
        reads.append(data["name"])
        return read(cls, data)

    monkeypatch.setattr(StudyDesign, "from_dict", classmethod(counted))
    assert main(["run", "--all", "--jobs", "1", "--db", db]) == 0
    assert reads == ["session test"]
    assert [t[2] for t in _trials(db)] == ["completed"] * 8


def test_a_terminal_apps_trial_reads_the_design_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The terminal app's trial (its probe step, then its session of one trial) reads
    the design once and hands it on; the probe step and the runner each read it."""
    from db.migrate import open_database
    from study.protocol.default_estimator import load_estimator
    from study.protocol.design import StudyDesign
    from study.tui.trial_runner import TrialRun

    db = _study(tmp_path)
    engine = open_database(db, create=False)
    estimator = load_estimator()
    reads: list[str] = []
    read = StudyDesign.from_dict.__func__  # type: ignore[attr-defined]

    def counted(cls, data):  # type: ignore[no-untyped-def]
        reads.append(data["name"])
        return read(cls, data)

    monkeypatch.setattr(StudyDesign, "from_dict", classmethod(counted))
    try:
        outcome = TrialRun(engine, estimator, "P001", "simulated", None).run()
    finally:
        engine.dispose()
    assert len(outcome.trial_ids) == 1
    assert reads == ["session test"]
