"""A read-only connection to an SQLite study database without SQLAlchemy, for commands
that only read (`study analyze`): importing SQLAlchemy and declaring the models costs
such a command more than its queries.

`plain_sqlite(db)` returns a `sqlite3` connection (opened read-only) when `db` (or
`STUDY_DB`, or the default) names an existing SQLite file, given as a path or as a
plain `sqlite:///PATH` URL, whose schema is at `HEAD_REVISION`; otherwise None, and the
caller opens the database through `db.migrate.open_database`, which upgrades an older
schema, refuses an unknown one, understands URL parameters and serves PostgreSQL.
"""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path
from urllib.parse import quote

from db.revision import HEAD_REVISION

DEFAULT_URL = "sqlite:///study.db"
"""`./study.db` in the working directory, used when neither `--db` nor `STUDY_DB` is set
(here rather than in `db.engine`, which imports SQLAlchemy)."""


def sqlite_file(db: str | None) -> Path | None:
    """The SQLite file `db` names as a path or a plain sqlite:/// URL, else None."""
    raw = db or os.environ.get("STUDY_DB") or DEFAULT_URL
    if "://" in raw:
        prefix = "sqlite:///"
        if not raw.startswith(prefix) or "?" in raw or raw == prefix:
            return None
        raw = raw[len(prefix) :]
    if raw == ":memory:":
        return None
    return Path(raw).expanduser()


def plain_sqlite(db: str | None) -> sqlite3.Connection | None:
    """A read-only connection to the current-schema SQLite database `db`, or None."""
    path = sqlite_file(db)
    if path is None or not path.is_file():
        return None
    try:
        conn = sqlite3.connect(f"file:{quote(str(path.resolve()))}?mode=ro", uri=True, timeout=30.0)
    except sqlite3.Error:
        return None
    try:
        revisions = conn.execute("SELECT version_num FROM alembic_version").fetchall()
    except sqlite3.Error:  # not a study database, or not readable: open_database says why
        revisions = []
    if revisions != [(HEAD_REVISION,)]:
        conn.close()
        return None
    return conn
