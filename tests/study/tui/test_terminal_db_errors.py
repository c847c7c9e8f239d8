"""The real `study tui` in a pseudo-terminal (80 x 24) on an SQLite study whose database
fails under it: read-only, locked by another program, or deleted mid-session. Each time
the app shows one plain line naming the cause (in the status of the participants
screen and in a notification), shows no traceback, still switches screens, and quits
cleanly with ctrl+q. The Pilot tests of the same cases are in
test_db_errors.py.
"""

from __future__ import annotations

import io
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

import pexpect
import pytest
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from db.models.study import Participant

F1, F2 = "\x1bOP", "\x1bOQ"
NOBODY = 65534


def words(*parts: str) -> str:
    """A pattern for `parts` drawn one after the other: between two of them the terminal
    may receive spaces, a line break of a wrapped notification, or style escapes."""
    gap = r"(?:\s|▌|\x1b\[[0-9;?]*[A-Za-z])+"
    return gap.join(re.escape(p) for p in parts)


class App:
    """`study tui --db DB` in a pseudo-terminal; everything it drew is in `self.drawn`."""

    def __init__(
        self,
        db: str,
        cwd: Path,
        prefix: Sequence[str] = (),
        env: dict | None = None,
        args: Sequence[str] = (),
    ):
        study = Path(sys.executable).with_name("study")
        env = {
            **os.environ,
            "TERM": "xterm-256color",
            "COLUMNS": "80",
            "LINES": "24",
            **(env or {}),
        }
        command, *args = [*prefix, str(study), "tui", "--db", db, *args]
        self.drawn = io.StringIO()
        self.child = pexpect.spawn(
            command,
            args,
            dimensions=(24, 80),
            env=env,
            cwd=str(cwd),
            timeout=60,
            encoding="utf-8",
        )
        self.child.logfile_read = self.drawn

    def loaded(self) -> None:
        """The overview, with the roster from the database."""
        self.child.expect("next trial: P001")

    def enrol(self) -> None:
        """The participants screen (F2) and its add key."""
        self.child.send(F2)
        self.child.expect("Enrol")  # its footer
        self.child.send("\x01")  # ctrl+a

    def refused(self, *cause: str) -> None:
        """The enrolment fails with a status line and a notification naming `cause`
        (and not, as it would without the behaviour, with a new participant)."""
        enrolled = words("enrolled", "P003")
        wrote = "the app enrolled P003: nothing stopped the write"
        assert self.child.expect([words("not", "enrolled:", "the"), enrolled]) == 0, wrote
        assert self.child.expect([words(*cause), enrolled]) == 0, wrote

    def still_answers(self) -> None:
        """The process is alive and switches screens: the overview (F1), then back to
        the participants (F2)."""
        assert self.child.isalive()
        self.child.send(F1)
        self.child.expect("Sessions done")
        self.child.send(F2)
        self.child.expect("Enrol")
        assert self.child.isalive()

    def quit(self) -> None:
        """ctrl+q (answering yes if the app asks), then the process ends with status 0."""
        self.child.sendcontrol("q")
        if self.child.expect([pexpect.EOF, r"[Qq]uit\?|without saving"]) == 1:
            self.child.send("y")
            self.child.expect(pexpect.EOF)
        self.child.wait()
        # the app's last screen and what it printed on leaving (a traceback) name the cause
        assert self.child.exitstatus == 0, self.drawn.getvalue()[-3000:]
        assert "Traceback" not in self.drawn.getvalue()

    def close(self) -> None:
        self.child.close(force=True)


def _participants(db: Path) -> int:
    from db.migrate import open_database

    engine = open_database(str(db), create=False)
    try:
        with Session(engine) as session:
            return session.scalar(select(func.count()).select_from(Participant)) or 0
    finally:
        engine.dispose()


@pytest.fixture
def study_file(study_engine: Engine) -> Path:
    """The SQLite file of the study (P001, P002 enrolled), closed by this process."""
    study_engine.dispose()
    return Path(str(study_engine.url.database))


@pytest.fixture
def read_only_study(study_file: Path) -> Iterator[tuple[Path, list[str]]]:
    """A copy of the study that the app cannot write, and the command prefix that runs
    the app: (file, prefix).

    File permissions are what a lab machine would have (the file `chmod 444`), but root
    ignores them; as root the app runs as the unprivileged user nobody through
    `setpriv --reuid 65534` (util-linux), with the study copied to a folder that nobody
    owns (the pytest folders are root's own, 0700). The folder stays writable so that
    SQLite can make the WAL index a reader of a WAL database needs.
    """
    folder = Path(tempfile.mkdtemp(prefix="study-ro-"))
    try:
        db = folder / "study.db"
        shutil.copy(study_file, db)
        prefix: list[str] = []
        if os.geteuid() == 0:
            setpriv = shutil.which("setpriv")
            if setpriv is None:
                pytest.skip("running as root without setpriv: a read-only file is writable")
            for path in (folder, db):
                os.chown(path, NOBODY, NOBODY)
            prefix = [setpriv, f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups"]
        os.chmod(db, 0o444)
        yield db, prefix
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_a_read_only_database_says_so_in_the_terminal_and_the_app_stays(
    read_only_study: tuple[Path, list[str]],
) -> None:
    db, prefix = read_only_study
    folder = db.parent
    app = App(str(db), folder, prefix, env={"HOME": str(folder)})
    try:
        app.loaded()
        app.enrol()
        app.refused("the", "database", "is", "read-only:", "nothing")
        app.still_answers()
        app.quit()
    finally:
        app.close()
    os.chmod(db, 0o644)
    assert _participants(db) == 2


@pytest.fixture
def locker(study_file: Path) -> Iterator[subprocess.Popen[str]]:
    """Another program holding `BEGIN EXCLUSIVE` on the study until it reads a line."""
    code = (
        "import sqlite3, sys\n"
        f"db = sqlite3.connect({str(study_file)!r}, isolation_level=None)\n"
        "db.execute('BEGIN EXCLUSIVE'); print('locked', flush=True)\n"
        "sys.stdin.readline(); db.execute('ROLLBACK'); db.close(); print('released', flush=True)\n"
    )
    process = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        yield process
    finally:
        process.kill()
        process.wait()


def _lock(locker: subprocess.Popen[str]) -> None:
    assert locker.stdout is not None
    assert locker.stdout.readline().strip() == "locked"


def _release(locker: subprocess.Popen[str]) -> None:
    assert locker.stdin is not None
    assert locker.stdout is not None
    locker.stdin.write("\n")
    locker.stdin.flush()
    assert locker.stdout.readline().strip() == "released"


def test_a_locked_database_says_so_in_the_terminal_then_enrols_when_released(
    study_file: Path, locker: subprocess.Popen[str]
) -> None:
    # the lock is taken once the app has loaded (a WAL database lets readers through
    # anyway); the app waits 2 s for it (?timeout=2, the default is 30 s), then says so
    app = App(f"sqlite:///{study_file}?timeout=2", study_file.parent)
    try:
        app.loaded()
        _lock(locker)
        app.enrol()
        app.refused("locked", "by", "another", "program")
        app.still_answers()
        _release(locker)
        app.child.send("\x01")  # the participants screen is open: ctrl+a enrols now
        app.child.expect(words("enrolled", "P003"))
        app.quit()
    finally:
        app.close()
    assert _participants(study_file) == 3


def test_a_database_file_removed_mid_session_is_named_in_the_terminal(study_file: Path) -> None:
    # an open SQLite connection would go on writing into the deleted file: the app
    # refuses instead and names the file
    app = App(str(study_file), study_file.parent)
    try:
        app.loaded()
        for suffix in ("", "-wal", "-shm"):
            Path(f"{study_file}{suffix}").unlink(missing_ok=True)
        app.enrol()
        app.refused("is", "gone", "(deleted", "or", "moved?):")
        app.still_answers()
        app.quit()
    finally:
        app.close()
    assert not study_file.exists()  # and no empty database was created in its place
