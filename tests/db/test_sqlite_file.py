"""An SQLite engine's busy timeout from the URL, and its file deleted or replaced under
it: refused with `DatabaseGoneError`, never written into, never recreated empty."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from sqlalchemy import text

from db.engine import SQLITE_BUSY_TIMEOUT_MS, make_engine
from db.errors import DatabaseGoneError, DbInputError


def _busy_timeout(url: str) -> int:
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            return int(conn.exec_driver_sql("PRAGMA busy_timeout").scalar_one())
    finally:
        engine.dispose()


def test_the_busy_timeout_comes_from_the_url(tmp_path: Path) -> None:
    db = tmp_path / "s.db"
    assert _busy_timeout(f"sqlite:///{db}") == SQLITE_BUSY_TIMEOUT_MS
    assert _busy_timeout(f"sqlite:///{db}?timeout=1.5") == 1500
    with pytest.raises(DbInputError, match="timeout='soon'; expected a number of seconds"):
        make_engine(f"sqlite:///{db}?timeout=soon")


@pytest.mark.parametrize("how", ["deleted", "replaced"])
def test_a_file_gone_under_an_open_engine_is_refused(tmp_path: Path, how: str) -> None:
    db = tmp_path / "s.db"
    engine = make_engine(f"sqlite:///{db}")
    try:
        with engine.begin() as conn:
            conn.execute(text("CREATE TABLE t (x INTEGER)"))
        for suffix in ("", "-wal", "-shm"):
            Path(f"{db}{suffix}").unlink(missing_ok=True)
        if how == "replaced":
            db.write_bytes(b"")
        with pytest.raises(DatabaseGoneError, match=f"the study database file {db} is gone"):
            with engine.begin() as conn:  # the pooled connection
                conn.execute(text("INSERT INTO t VALUES (1)"))
        engine.dispose()
        with pytest.raises(DatabaseGoneError):
            engine.connect()  # a new connection
    finally:
        engine.dispose()
    assert os.path.exists(db) == (how == "replaced")  # nothing created in its place
