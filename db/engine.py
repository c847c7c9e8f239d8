"""Engines for the two supported backends, and the transaction helpers every writer uses.

SQLite (the embedded default) is set up on every new connection: WAL journal so that
readers (the TUI, `study schedule`) never block the session writing samples, foreign
keys on, `synchronous=FULL` so a committed chunk survives a power cut (`durable=False`:
`synchronous=NORMAL`, see `make_engine`), and a busy timeout so that two processes
writing at once wait instead of failing (30 s, or `?timeout=SECONDS` in the URL). pysqlite's own
implicit transaction handling is switched off and `BEGIN` is emitted by SQLAlchemy
(the recipe in SQLAlchemy's SQLite dialect documentation), which makes transactional
DDL work for Alembic and lets `write_transaction` take the write lock up front.

PostgreSQL (multi-site studies) needs nothing special beyond `pool_pre_ping`; the
same `write_transaction` serialises competing writers with an advisory lock.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any
from urllib.parse import quote

from sqlalchemy import Connection, Engine, create_engine, event
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError, NoSuchModuleError
from sqlalchemy.orm import Session, sessionmaker

from db.errors import DatabaseGoneError, DbInputError
from db.plain import DEFAULT_URL

SQLITE_BUSY_TIMEOUT_MS = 30_000

_WRITE_LOCK_KEY = 7_240_001
"""PostgreSQL advisory lock taken by `write_transaction` (an arbitrary project constant)."""


def resolve_url(db: str | URL | None = None) -> URL:
    """The database URL from `--db`, else `STUDY_DB`, else `./study.db`.

    Parameters
    ----------
    db : str or URL or None, optional
        A URL (`sqlite:///FILE`, `postgresql+psycopg://USER@HOST:PORT/DB`), a path to an
        SQLite file (a value without `://`), or None for the environment's or the
        default.

    Returns
    -------
    URL
        The parsed URL, its SQLite parameters checked.

    Raises
    ------
    DbInputError
        The text is no URL, names another backend, or has an SQLite parameter
        `study` does not know (`SQLITE_QUERY`) or a value out of range.
    """
    if isinstance(db, URL):
        return db
    raw = db or os.environ.get("STUDY_DB") or DEFAULT_URL
    if "://" not in raw:
        return URL.create("sqlite", database=str(Path(raw).expanduser()))
    try:
        url = make_url(raw)
    except (ArgumentError, ValueError):  # ValueError: a port that is not a number
        raise DbInputError(
            f"database URL {raw!r} is not a URL; expected e.g. sqlite:///study.db "
            "or postgresql+psycopg://user@host:5432/dbname"
        ) from None
    if url.get_backend_name() not in ("sqlite", "postgresql"):
        raise DbInputError(
            f"database URL {url.render_as_string(hide_password=True)!r} uses backend "
            f"{url.get_backend_name()!r}; expected sqlite or postgresql"
        )
    if url.get_backend_name() == "sqlite":
        _check_sqlite_query(url)
        url = _as_sqlite_uri(url)
    return url


def _as_sqlite_uri(url: URL) -> URL:
    """An SQLite URL whose `mode` or `immutable` takes effect: they are parameters of
    SQLite's URI filenames, which need `uri=true` (without it pysqlite ignores them, and
    the database would be opened for writing) and a database written `file:PATH`
    (pysqlite otherwise takes `PATH?mode=ro` as a file name, and creates an empty
    database of that name). `sqlite:///PATH?mode=ro` and `...&uri=true` both become
    `sqlite:///file:PATH?mode=ro&uri=true`."""

    query = dict(url.query)
    database = url.database or ""
    if not {"mode", "immutable"} & set(query) or database in ("", ":memory:"):
        return url
    query["uri"] = "true"
    if not database.startswith("file:"):
        database = f"file:{quote(str(Path(database).expanduser().absolute()))}"
    return url.set(database=database, query=query)


SQLITE_QUERY = {
    "timeout": "seconds from 0 to 86400",
    "mode": "ro, rw, rwc or memory",
    "immutable": "1",
    "uri": "true",
}
"""The SQLite URL parameters `study` understands (pysqlite's); any other is a typo."""
MAX_TIMEOUT_S = 86400.0


def _check_sqlite_query(url: URL) -> None:
    for key, value in url.query.items():
        if key not in SQLITE_QUERY:
            raise DbInputError(
                f"database URL {describe(url)!r} has parameter {key!r}; expected only "
                f"{', '.join(SQLITE_QUERY)}"
            )
        text = value if isinstance(value, str) else value[-1]
        ok = {
            "timeout": lambda t: _seconds(t) is not None,
            "mode": lambda t: t in ("ro", "rw", "rwc", "memory"),
            "immutable": lambda t: t == "1",
            "uri": lambda t: t == "true",
        }[key](text)
        if not ok:
            raise DbInputError(
                f"database URL {describe(url)!r} has {key}={text!r}; expected "
                f"{SQLITE_QUERY[key]}" + (", e.g. ?timeout=30" if key == "timeout" else "")
            )


def _seconds(text: str) -> float | None:
    """A timeout in seconds, 0 to a day, or None."""

    try:
        seconds = float(text)
    except ValueError:
        return None
    return seconds if math.isfinite(seconds) and 0 <= seconds <= MAX_TIMEOUT_S else None


def describe(url: URL | Engine) -> str:
    """The URL as it can be shown to a user.

    Parameters
    ----------
    url : URL or Engine
        A URL, or an engine whose URL is meant.

    Returns
    -------
    str
        The URL with its password hidden.
    """
    if isinstance(url, Engine):
        url = url.url
    database = url.database or ""
    if url.get_backend_name() == "sqlite" and database.startswith("file:"):
        from urllib.parse import unquote

        read_only = " (read-only)" if url.query.get("mode") == "ro" else ""
        return f"sqlite:///{unquote(database.removeprefix('file:'))}{read_only}"
    return url.render_as_string(hide_password=True)


def is_sqlite(bind: Engine | Connection) -> bool:
    """Whether `bind` (an engine or a connection) talks to SQLite.

    Parameters
    ----------
    bind : Engine or Connection
        An engine or a connection.

    Returns
    -------
    bool
        True for SQLite, False for any other backend (PostgreSQL).
    """
    return bind.dialect.name == "sqlite"


def make_engine(url: str | URL, *, durable: bool = True) -> Engine:
    """An engine for `url` with the per-backend settings described in the module docstring.

    Parameters
    ----------
    url : str or URL
        A database URL (see `resolve_url`).
    durable : bool, optional
        SQLite: every commit synced to the disk (`synchronous=FULL`: a committed chunk
        survives a power cut). False: `synchronous=NORMAL`, no sync per commit (in WAL
        mode a power cut can lose the last commits, never the file's consistency), for a
        database that is thrown away when it is not finished, as `study demo`'s: its
        chunks of samples, one commit per second of trial time, each waited for a sync.

    Returns
    -------
    Engine
        SQLite: WAL (unless in memory or read-only), foreign keys on, the busy timeout
        of `busy_timeout_ms`, and a watch for the file being deleted or moved;
        PostgreSQL: connections checked before use.

    Raises
    ------
    DbInputError
        The URL names a driver that is not installed or cannot be used.
    """
    url = make_url(url) if isinstance(url, str) else url
    try:
        if url.get_backend_name() == "sqlite":
            timeout_ms = busy_timeout_ms(url)
            engine = create_engine(url, connect_args={"timeout": timeout_ms / 1000})
            # An in-memory or read-only (?mode=ro) database cannot switch to WAL.
            wal = url.database not in (None, "", ":memory:") and url.query.get("mode") != "ro"
            _configure_sqlite(engine, wal=wal, busy_timeout_ms=timeout_ms, durable=durable)
            if wal and url.database and not url.query.get("uri"):
                _watch_sqlite_file(engine, Path(url.database))
        else:
            engine = create_engine(url, pool_pre_ping=True)
    except (NoSuchModuleError, ArgumentError) as exc:
        raise DbInputError(
            f"cannot use database URL {describe(url)!r}: {exc}; "
            "expected sqlite:///FILE or postgresql+psycopg://..."
        ) from None
    return engine


def busy_timeout_ms(url: URL) -> int:
    """How long a writer waits for another's lock.

    Parameters
    ----------
    url : URL
        An SQLite URL, possibly with `?timeout=SECONDS` (as pysqlite spells it).

    Returns
    -------
    int
        The timeout in milliseconds: the URL's, else `SQLITE_BUSY_TIMEOUT_MS`.

    Raises
    ------
    DbInputError
        The timeout is not a number of seconds from 0 to `MAX_TIMEOUT_S`.
    """
    raw = url.query.get("timeout")
    if raw is None:
        return SQLITE_BUSY_TIMEOUT_MS
    text = raw if isinstance(raw, str) else raw[-1]
    seconds = _seconds(text)
    if seconds is None:
        raise DbInputError(
            f"database URL {describe(url)!r} has timeout={text!r}; expected a number of "
            "seconds, e.g. ?timeout=30"
        )
    return round(seconds * 1000)


def _configure_sqlite(
    engine: Engine, *, wal: bool, busy_timeout_ms: int, durable: bool = True
) -> None:
    synchronous = "FULL" if durable else "NORMAL"

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        # Let SQLAlchemy, not pysqlite, decide when a transaction begins.
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        if wal:
            cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.execute(f"PRAGMA synchronous={synchronous}")
        cursor.execute(f"PRAGMA busy_timeout={busy_timeout_ms}")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn: Connection) -> None:
        mode = conn.get_execution_options().get("sqlite_begin", "")
        conn.exec_driver_sql(f"BEGIN {mode}".strip())


def _watch_sqlite_file(engine: Engine, path: Path) -> None:
    """Refuse every transaction once the SQLite file is no longer at `path`.

    An open SQLite connection keeps a deleted or renamed file (and its WAL) open and
    goes on committing into it, so that what is written after `rm study.db` is lost
    without a word; a new connection would create an empty file at the path. Once the
    file has been opened, each transaction and each new connection first checks that the
    same file is still there, and raises `DatabaseGoneError` if not.
    """
    path = path.expanduser().absolute()
    identity: list[tuple[int, int]] = []  # (device, inode) of the file first opened

    def still_there() -> None:
        if not identity:
            return
        try:
            st = os.stat(path)
        except FileNotFoundError:
            st = None
        if st is None or (st.st_dev, st.st_ino) != identity[0]:
            raise DatabaseGoneError(
                f"the study database file {path} is gone (deleted or moved?): nothing "
                "was written; put it back there and restart"
            )

    @event.listens_for(engine, "do_connect")
    def _before_connect(_dialect: Any, _record: Any, _cargs: Any, _cparams: Any) -> None:
        still_there()

    @event.listens_for(engine, "connect")
    def _connected(_dbapi_connection: Any, _record: Any) -> None:
        if not identity:
            st = os.stat(path)
            identity.append((st.st_dev, st.st_ino))

    @event.listens_for(engine, "begin", insert=True)  # before BEGIN is sent
    def _before_begin(_conn: Connection) -> None:
        still_there()


@contextmanager
def write_transaction(engine: Engine, *, lock_wait_ms: int | None = None) -> Iterator[Connection]:
    """A transaction that holds the database's write lock from its first statement.

    Use it for read-then-write work that must not interleave with another process
    (the next participant code, a schema upgrade). SQLite: `BEGIN IMMEDIATE`;
    PostgreSQL: a transaction-scoped advisory lock.

    Parameters
    ----------
    engine : Engine
        The study database.
    lock_wait_ms : int, optional
        SQLite: how long to wait for another program's lock before the `database is
        locked` error, instead of the busy timeout (`busy_timeout_ms`), for a caller
        that polls and can do something else meanwhile.

    Yields
    ------
    Connection
        A connection inside the transaction; it commits when the block ends without an
        exception and rolls back otherwise.
    """
    with engine.connect() as conn:
        sqlite = is_sqlite(conn)
        with _lock_wait(conn, engine, lock_wait_ms if sqlite else None):
            if sqlite:
                conn.execution_options(sqlite_begin="IMMEDIATE")
            with conn.begin():
                if not sqlite:
                    conn.exec_driver_sql(f"SELECT pg_advisory_xact_lock({_WRITE_LOCK_KEY})")
                yield conn


@contextmanager
def _lock_wait(conn: Connection, engine: Engine, wait_ms: int | None) -> Iterator[Any]:
    """Within it, SQLite's busy timeout on `conn` is `wait_ms` (None: left as it is),
    then back to the engine's (`busy_timeout_ms`); yields the driver's connection. Set on
    the driver's connection: through SQLAlchemy the PRAGMA would begin a transaction of
    its own."""
    driver = conn.connection.driver_connection
    if wait_ms is None or driver is None:
        yield None
        return
    driver.execute(f"PRAGMA busy_timeout={int(wait_ms)}")
    try:
        yield driver
    finally:
        driver.execute(f"PRAGMA busy_timeout={busy_timeout_ms(engine.url)}")


def checkpoint(engine: Engine, *, wait_ms: int = 1000) -> None:
    """SQLite: move the write-ahead log's commits into the database file and empty the
    log, so that the file alone holds every commit (a copy of it taken now, without its
    `-wal` beside it, misses nothing). Processes that end without closing their
    connections (a pool's workers) leave the log full; the last connection to close
    would do this, but those never close. Nothing to do on PostgreSQL.

    Parameters
    ----------
    engine : Engine
        The study database.
    wait_ms : int
        How long to wait for another program's write or long read to end (the busy
        timeout would hold a caller that is only tidying up for 30 s); past it the log
        keeps what is not yet folded in, and nothing is lost.
    """
    if engine.dialect.name != "sqlite":
        return
    with engine.connect() as conn, _lock_wait(conn, engine, wait_ms) as driver:
        if driver is not None:  # else not a live SQLite connection: nothing to fold in
            driver.execute("PRAGMA wal_checkpoint(TRUNCATE)")


def make_session_factory(engine: Engine) -> sessionmaker[Session]:
    """ORM sessions bound to `engine`.

    Parameters
    ----------
    engine : Engine
        The study database.

    Returns
    -------
    sessionmaker
        A session factory whose objects stay readable after commit.
    """
    return sessionmaker(engine, expire_on_commit=False)
