"""`db.plain`: the SQLAlchemy-free read-only connection is given only for an SQLite file
at the current schema; everything else goes through `open_database`."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from db.migrate import HEAD_REVISION, open_database
from db.plain import plain_sqlite, sqlite_file


def test_a_current_sqlite_file_opens_read_only(tmp_path: Path) -> None:
    path = tmp_path / "s.db"
    open_database(str(path)).dispose()
    for name in (str(path), f"sqlite:///{path}"):
        conn = plain_sqlite(name)
        assert conn is not None
        try:
            assert conn.execute("SELECT version_num FROM alembic_version").fetchall() == [
                (HEAD_REVISION,)
            ]
            with pytest.raises(sqlite3.OperationalError, match="readonly"):
                conn.execute("DELETE FROM participants")
        finally:
            conn.close()


def test_anything_else_is_left_to_open_database(tmp_path: Path) -> None:
    older = tmp_path / "older.db"
    with sqlite3.connect(older) as conn:
        conn.execute("CREATE TABLE alembic_version (version_num VARCHAR(32))")
        conn.execute("INSERT INTO alembic_version VALUES ('0007_an_older_one')")
    foreign = tmp_path / "foreign.db"
    with sqlite3.connect(foreign) as conn:
        conn.execute("CREATE TABLE t (x)")
    (tmp_path / "junk.db").write_bytes(b"not a database at all, just bytes" * 10)
    current = tmp_path / "s.db"
    open_database(str(current)).dispose()
    for name in (
        str(older),  # upgraded by open_database
        str(foreign),  # refused by open_database
        str(tmp_path / "junk.db"),
        str(tmp_path / "missing.db"),
        f"sqlite:///{current}?timeout=5",  # parameters: SQLAlchemy's URL handling
        "postgresql+psycopg://u@h/db",
    ):
        assert plain_sqlite(name) is None, name
    assert sqlite_file(":memory:") is None
    assert sqlite_file("sqlite:///") is None
