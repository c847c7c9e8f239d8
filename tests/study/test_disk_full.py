"""A full disk and a lock, for real: `study run` on a small tmpfs that fills up during a
session, and commands against an SQLite file another connection holds locked.

The message after a full disk names the participant, the trial and the time up to which
its samples were kept, and those are what the database holds; releasing the session
lease on the full disk does not replace that message. Mounting a tmpfs needs root (and
a kernel that lets this process mount); elsewhere the test is skipped, saying so.
"""

from __future__ import annotations

import os
import re
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from contextlib import closing
from pathlib import Path

import pytest

from study.cli import main
from study.protocol.design import TEMPLATE

STUDY = [sys.executable, "-c", "import sys; from study.cli import main; sys.exit(main())"]


@pytest.fixture
def small_tmpfs(tmp_path: Path) -> Iterator[Path]:
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    where = tmp_path / "tmpfs"
    where.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(where)],
        capture_output=True,
        text=True,
    )
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def _study(folder: Path) -> str:
    (folder / "d.toml").write_text(TEMPLATE)
    db = str(folder / "s.db")
    assert main(["init", "--design", str(folder / "d.toml"), "--db", db]) == 0
    assert main(["participant", "add", "--group", "novice", "--db", db]) == 0
    return db


def _fill(folder: Path, leave_kib: int) -> Path:
    """A file taking all but `leave_kib` KiB of the file system's free space."""
    stat = os.statvfs(folder)
    free = stat.f_bavail * stat.f_frsize
    filler = folder / "filler"
    with filler.open("wb") as f:
        f.write(b"\0" * max(free - leave_kib * 1024, 0))
    return filler


@pytest.mark.parametrize("leave_kib", [250, 600])  # 600: releasing the lease fails too
def test_a_full_disk_names_the_participant_trial_and_time_kept(
    small_tmpfs: Path, leave_kib: int
) -> None:
    db = _study(small_tmpfs)
    filler = _fill(small_tmpfs, leave_kib)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    out = subprocess.run(
        [*STUDY, "run", "--participant", "P001", "--db", db],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    err = out.stderr.strip().splitlines()
    assert out.returncode == 2, out.stderr
    assert len(err) == 1, err  # one line: not followed by a second error from the lease
    assert "nothing more was stored" not in err[0]
    found = re.search(
        r"storing P001's (\w+)/(\w+) (practice trial|trial) (\d+) failed \((.*full.*)\): kept "
        r"(\d+) trial\(s\) of P001 completed in this session and (?:its samples up to t = "
        r"([0-9.]+) s|no samples) of ",
        err[0],
    )
    assert found, err[0]
    task, condition, kind, number, _, n_completed, kept_s = found.groups()
    with closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as conn:
        completed = conn.execute("SELECT count(*) FROM trials WHERE status = 'completed'")
        assert completed.fetchone()[0] == int(n_completed)
        running = conn.execute(
            "SELECT t.task, t.condition, t.practice, t.trial_index, max(s.t_last_s) FROM trials t "
            "LEFT JOIN sample_chunks s ON s.trial_id = t.id WHERE t.status = 'running' "
            "GROUP BY t.id"
        ).fetchall()
    assert len(running) == 1
    r_task, r_condition, practice, index, last_s = running[0]
    assert (r_task, r_condition, bool(practice), index + 1) == (
        task,
        condition,
        kind == "practice trial",
        int(number),
    )
    assert (last_s is None and kept_s is None) or float(kept_s) == pytest.approx(last_s, abs=0.005)
    # with space again, the next run marks it interrupted and finishes the schedule
    filler.unlink()
    again = subprocess.run(
        [*STUDY, "run", "--participant", "P001", "--db", db],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert again.returncode == 0, again.stderr
    with closing(sqlite3.connect(db)) as conn:
        statuses = dict(conn.execute("SELECT status, count(*) FROM trials GROUP BY status"))
    assert statuses == {"completed": 8, "interrupted": 1}  # 2 blocks x (1 practice + 3)


def test_a_backup_to_a_full_disk_names_the_folder_and_leaves_nothing(
    small_tmpfs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = _study(tmp_path)  # the database on a disk with room, the copy's folder full
    before = Path(db).read_bytes()
    _fill(small_tmpfs, 20)
    capsys.readouterr()
    out = small_tmpfs / "backups" / "today"
    assert main(["db", "backup", "--out", str(out), "--db", db]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"backup to {out} failed: no space left for the copy" in err[0], err
    assert "expected a writable folder with free space" in err[0]
    assert "is full" not in err[0].split("(")[0]  # the study database is not blamed
    assert sorted(p.name for p in small_tmpfs.iterdir()) == ["filler"]  # no empty folders
    assert Path(db).read_bytes() == before


def test_a_locked_database_is_named_as_locked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = _study(tmp_path)
    with closing(sqlite3.connect(db, isolation_level=None)) as holder:
        holder.execute("BEGIN IMMEDIATE")  # another program's write lock
        capsys.readouterr()
        url = f"sqlite:///{db}?timeout=0.2"
        for argv in (
            ["participant", "add", "--group", "novice", "--db", url],
            ["run", "--participant", "P001", "--db", url],
        ):
            assert main(argv) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1, err
            assert "is locked by another program (database is locked)" in err[0], err
            assert "?timeout=SECONDS" in err[0]
            assert "backup" not in err[0]
        holder.execute("ROLLBACK")
    with closing(sqlite3.connect(db)) as conn:  # nothing half-written
        assert conn.execute("SELECT count(*) FROM participants").fetchone()[0] == 1
        assert conn.execute("SELECT count(*) FROM session_leases").fetchone()[0] == 0
