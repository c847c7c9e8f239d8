"""The real `study tui` at 80 x 24 on an SQLite study made immutable while no program
had it open: the database file, its -wal and its -shm (`chattr +i`, which binds root
too). A note is refused with a line saying the database is read-only (not that the file
cannot be read, nor that a restart is needed), nothing says "not withdrawn", and the
note typed stays in its dialog."""

from __future__ import annotations

import shutil
import sqlite3
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.study.tui import test_terminal_db_errors as terminal
from tests.study.tui.test_terminal_db_errors import F2, App, words

study_file = terminal.study_file


def _chattr(flag: str, *paths: Path) -> bool:
    chattr = shutil.which("chattr")
    if chattr is None:
        return False
    done = subprocess.run([chattr, flag, *map(str, paths)], capture_output=True)
    return done.returncode == 0


@pytest.fixture
def immutable_study(study_file: Path) -> Iterator[Path]:
    """A copy of the study whose file, -wal and -shm are immutable. The -wal and -shm
    are made by a connection that reads the study (WAL mode) and are left when it closes
    (it cannot delete them once they are immutable)."""
    folder = Path(tempfile.mkdtemp(prefix="study-immutable-"))
    db = folder / "study.db"
    shutil.copy(study_file, db)
    files = [db, Path(f"{db}-wal"), Path(f"{db}-shm")]
    reader = sqlite3.connect(db)
    try:
        assert reader.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        reader.execute("SELECT count(*) FROM participants").fetchone()
        assert all(f.exists() for f in files)
        if not _chattr("+i", *files):
            pytest.skip("chattr +i needs root on a file system with attributes (ext4, xfs)")
        reader.close()
        yield db
    finally:
        reader.close()
        _chattr("-i", *files)
        shutil.rmtree(folder, ignore_errors=True)


def test_a_note_on_an_immutable_database_says_read_only_and_is_kept(
    immutable_study: Path,
) -> None:
    db = immutable_study
    app = App(str(db), db.parent)
    try:
        app.loaded()
        app.child.send(F2)
        app.child.expect("Session note")
        app.child.send("\x0f")  # ctrl+o
        app.child.expect(words("contact", "details"))
        app.child.send("dial recalibrated\r")
        app.child.expect(words("note", "not", "kept:", "the", "database", "is", "read-only"))
        drawn = app.drawn.getvalue()
        assert "not withdrawn" not in drawn
        assert "cannot be read" not in drawn
        assert "restart" not in drawn
        app.child.expect("dial recalibrated")  # the dialog is offered again, as typed
        app.child.send("\x1b")
        app.still_answers()
        app.quit()
    finally:
        app.close()
