"""The end of a lab day: check the study database and keep a consistent copy of it.

`check_database` says whether the database can be trusted, in one line:

- SQLite: `PRAGMA integrity_check` (every page, every index against its table) and
  `PRAGMA foreign_key_check` (rows pointing at rows that are gone);
- PostgreSQL: there is no integrity pragma (the `amcheck` extension is not there by
  default), so every table's rows are counted (a page the server cannot read fails the
  query) and checked for rows pointing at rows that are gone, as SQLite's foreign-key
  check does; the copy below reads every row and every sample chunk in full;
- both: the schema is at the newest revision.

`backup_database` writes one SQLite file that is a complete, consistent study database
(`study tui --db COPY` opens it):

- SQLite: `VACUUM INTO`, which copies one read snapshot, so writers of another program
  (a session running meanwhile) neither block it nor make it inconsistent;
- PostgreSQL, without `pg_dump` (not on every lab machine, and its version must match
  the server's): every table copied row by row, in the schema's order, inside one
  REPEATABLE READ transaction (one snapshot), into a new SQLite database made at the
  same revision.

The copy is written under a temporary name, checked with `check_database` and row
counts equal to the snapshot's, and only then renamed; it is never left half-written.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import sqlite3
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy import Connection, Engine, Table, create_engine, func, insert, select
from sqlalchemy.exc import DBAPIError
from sqlalchemy.pool import NullPool

from db.base import Base
from db.engine import describe, is_sqlite
from db.migrate import current_revision, head_revision, open_database

__all__ = ["BackupResult", "CheckResult", "backup_database", "check_database"]

_MAX_LISTED = 5
"""Problems named in the one line (the rest are counted)."""
_COPY_BATCH = 500
"""Rows inserted per statement when PostgreSQL is copied (sample chunks are ~10 kB)."""


@dataclass(frozen=True)
class CheckResult:
    """What `check_database` found."""

    database: str
    """The database as it can be shown (password hidden)."""
    rows: dict[str, int] = field(default_factory=dict)
    """Rows per table (the schema's tables)."""
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def line(self) -> str:
        """One line: ok with the tables and rows read, or the problems found."""
        if self.ok:
            return (
                f"{self.database}: integrity ok ({len(self.rows)} tables, "
                f"{sum(self.rows.values()):,} rows)"
            )
        shown = "; ".join(self.problems[:_MAX_LISTED])
        more = len(self.problems) - _MAX_LISTED
        return (
            f"{self.database}: {len(self.problems)} integrity problem"
            f"{'' if len(self.problems) == 1 else 's'}: {shown}"
            f"{f'; {more} more' if more > 0 else ''}"
        )


@dataclass(frozen=True)
class BackupResult:
    """The copy `backup_database` wrote, and the check of the copy."""

    source: CheckResult
    path: Path
    size_bytes: int
    sha256: str
    copy: CheckResult

    def line(self) -> str:
        """One line: the source's check, the copy, its size, digest and check."""
        if not self.source.ok:
            return self.source.line()
        state = "checked ok" if self.copy.ok else f"NOT ok: {'; '.join(self.copy.problems[:2])}"
        return (
            f"{self.source.line()}; copy {self.path} ({self.size_bytes / 1e6:.1f} MB, "
            f"sha256 {self.sha256[:12]}) {state}"
        )


def _tables() -> list[Table]:
    import db.models  # noqa: F401  (every model's table on Base.metadata)

    return list(Base.metadata.sorted_tables)


def _count_rows(conn: Connection) -> dict[str, int]:
    return {t.name: int(conn.scalar(select(func.count()).select_from(t)) or 0) for t in _tables()}


def _dangling_references(conn: Connection) -> list[str]:
    """Rows whose foreign key names a row that does not exist (what SQLite's
    `foreign_key_check` finds; PostgreSQL enforces it, so this finds damage only)."""
    problems = []
    for table in _tables():
        for fk in table.foreign_key_constraints:
            [(col, ref)] = list(zip(fk.columns, fk.elements, strict=True))[:1]
            target = ref.column
            missing = (
                select(func.count())
                .select_from(table)
                .where(
                    col.is_not(None),
                    ~select(target).where(target == col).exists(),
                )
            )
            n = int(conn.scalar(missing) or 0)
            if n:
                problems.append(
                    f"{n} row{'' if n == 1 else 's'} of {table.name} refer to a missing "
                    f"{target.table.name} ({col.name})"
                )
    return problems


def _first_line(exc: BaseException) -> str:
    lines = str(getattr(exc, "orig", None) or exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__


def _integrity(conn: Connection) -> list[str]:
    if not is_sqlite(conn):
        return _dangling_references(conn)
    found = [
        line.strip()
        for r in conn.exec_driver_sql("PRAGMA integrity_check")
        for line in str(r[0]).splitlines()
        if line.strip() and not line.startswith("*** in database")
    ]
    problems = [] if found == ["ok"] else found
    for table, rowid, parent, _ in conn.exec_driver_sql("PRAGMA foreign_key_check"):
        problems.append(f"{table} row {rowid} refers to a missing {parent}")
    return problems


def _check(conn: Connection, shown: str) -> CheckResult:
    problems: list[str] = []
    rows: dict[str, int] = {}
    try:
        problems.extend(_integrity(conn))
        revision, head = current_revision(conn), head_revision()
        if revision != head:
            problems.append(f"schema at revision {revision}, expected {head}")
        rows = _count_rows(conn)
    except DBAPIError as exc:  # a page so damaged that reading it fails: named, not raised
        problems.append(f"the database cannot be read through ({_first_line(exc)})")
    return CheckResult(shown, rows, problems)


@contextlib.contextmanager
def _snapshot(engine: Engine) -> Iterator[Connection]:
    """A connection whose reads all see one snapshot (PostgreSQL: REPEATABLE READ)."""
    with engine.connect() as conn:
        if not is_sqlite(conn):
            conn = conn.execution_options(isolation_level="REPEATABLE READ")
        yield conn


def check_database(engine: Engine) -> CheckResult:
    """Check the database (see the module's docstring); never writes."""
    with _snapshot(engine) as conn:
        return _check(conn, describe(engine))


def _stamp(now: datetime | None) -> str:
    return (now or datetime.now(UTC)).astimezone(UTC).strftime("%Y%m%dT%H%M%SZ")


def _copy_name(engine: Engine, now: datetime | None) -> str:
    url = engine.url
    if url.get_backend_name() == "sqlite" and url.database:
        stem = Path(url.database).stem
    else:
        stem = url.database or "study"
    return f"{stem}-{_stamp(now)}.db"


def _copy_postgresql(source: Connection, target: Engine) -> dict[str, int]:
    """Copy every table of the schema, rows in key order, into `target`; return the
    rows per table of the source's snapshot."""
    counts = _count_rows(source)
    with target.begin() as out:
        for table in reversed(_tables()):  # rows the migrations seeded: the source has them
            out.execute(table.delete())
        for table in _tables():
            rows = source.execution_options(yield_per=_COPY_BATCH).execute(
                select(table).order_by(*table.primary_key.columns)
            )
            for batch in rows.mappings().partitions(_COPY_BATCH):
                out.execute(insert(table), [dict(r) for r in batch])
    return counts


def _make_folders(out_dir: Path) -> list[Path]:
    """Make `out_dir` and its missing parents; return the folders made, deepest first."""
    made = [p for p in (out_dir, *out_dir.parents) if not p.exists()]
    out_dir.mkdir(parents=True, exist_ok=True)
    return made


def _copy_failure(exc: BaseException, part: Path) -> OSError | None:
    """The OSError a failed write of the copy means, or None for any other failure.

    SQLite reports a full or failing target of `VACUUM INTO` (and of the PostgreSQL
    copy's SQLite file) as a database error; it is the copy's folder that is full, not
    the study database, so the caller's message must name the folder."""

    cause = getattr(exc, "orig", exc)  # SQLAlchemy wraps the driver's error
    if not isinstance(cause, sqlite3.Error):
        return None
    text = str(cause)
    if "full" in text:
        return OSError(errno.ENOSPC, f"no space left for the copy ({text})", str(part))
    if "disk I/O" in text or "unable to open" in text:
        return OSError(errno.EIO, f"the copy could not be written ({text})", str(part))
    return None


def backup_database(
    engine: Engine,
    out_dir: Path,
    *,
    now: datetime | None = None,
    notice: Callable[[str], None] = lambda _: None,
    replace_file: Callable[[Path, Path], object],
) -> BackupResult:
    """Check the database, then write a checked copy to `out_dir/NAME-STAMP.db`.

    The source is checked first; a source with problems is not copied (its result says
    why, and no file is written). Raises OSError when `out_dir` cannot be written.

    Parameters
    ----------
    engine : Engine
        The study database to copy (SQLite or PostgreSQL).
    out_dir : Path
        Folder for the copy; made if missing.
    now : datetime, optional
        The time stamped into the copy's name [the current time].
    notice : callable, optional
        Called with a line for each step (checking, copying, checking the copy).
    replace_file : callable
        Puts the checked temporary copy in place: ``replace_file(temporary, path)``.
        The application passes the project's one atomic write
        (`teleop_core.files.replace_durably`: the file and the rename flushed to disk);
        `db` imports nothing from `teleop_core`, so it takes the function as an argument.

    Returns
    -------
    BackupResult
        The source's check, the copy's path, size, SHA-256 and the copy's check.
    """
    notice("checking the database")
    source_check = check_database(engine)
    path = out_dir / _copy_name(engine, now)
    if not source_check.ok:
        return BackupResult(source_check, path, 0, "", CheckResult(str(path)))
    made = _make_folders(out_dir)
    part = out_dir / f".{path.name}.part"
    part.unlink(missing_ok=True)
    try:
        # made empty and private first (VACUUM INTO fills an empty file): the copy holds
        # what the database holds, so it is read and written by its owner alone, as the
        # exports are (their temporary files are made 600)
        os.close(os.open(part, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        notice(f"copying to {path}")
        with _snapshot(engine) as conn:
            if is_sqlite(conn):
                # outside any transaction (SQLAlchemy would begin one): the driver's own
                raw = conn.connection.driver_connection
                assert raw is not None  # an open connection has its driver's
                raw.execute("VACUUM INTO ?", (str(part),))
                expected = None  # writers may add rows after the snapshot: counted below
            else:
                target = open_database(f"sqlite:///{part}", create=True)
                try:
                    expected = _copy_postgresql(conn, target)
                finally:
                    target.dispose()
        notice("checking the copy")
        copy_engine = create_engine(f"sqlite:///{part}", poolclass=NullPool)
        try:
            with copy_engine.connect() as conn:
                copy_check = _check(conn, str(path))
                if copy_check.ok and expected is not None and copy_check.rows != expected:
                    differ = [t for t in expected if expected[t] != copy_check.rows.get(t)]
                    copy_check.problems.append(f"rows differ from the source in {differ}")
        finally:
            copy_engine.dispose()
        if Path(f"{part}-wal").exists():  # closed without a checkpoint: not a whole file
            raise OSError(f"the copy {part} kept a write-ahead log; expected it folded in")
        Path(f"{part}-shm").unlink(missing_ok=True)
        replace_file(part, path)
    except BaseException as exc:
        for suffix in ("", "-wal", "-shm"):
            Path(f"{part}{suffix}").unlink(missing_ok=True)
        for folder in made:  # the folders this call made, deepest first, if left empty
            with contextlib.suppress(OSError):
                folder.rmdir()
        copy_failure = _copy_failure(exc, part)
        if copy_failure is not None:
            raise copy_failure from exc
        raise
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return BackupResult(source_check, path, path.stat().st_size, digest.hexdigest(), copy_check)
