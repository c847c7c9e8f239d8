"""Schema revisions: create, recognise and upgrade study databases with Alembic.

Every database the tool opens goes through `open_database`. An empty database is
brought to the newest revision (that is how a study database is created); an older
one is upgraded in place, after an SQLite file has been copied aside as
`NAME.before-REV.bak`; a database at a revision this version does not know, or one that
holds tables but no revision at all, is refused with one line, never recreated.

The migration scripts live in `db/migrations/versions`; `autogenerate_revision` is the
developer's helper for writing the next one from the models.

Alembic is imported only when a schema has to be created, upgraded or compared with
the revision tree. Opening a database that is already at `HEAD_REVISION` (every start
of `study tui` and most commands) reads the `alembic_version` table with one query:
importing Alembic costs about 0.3 s on the lab machines, a fifth of the terminal app's
start-up budget. A test keeps `HEAD_REVISION` equal to the head of the shipped scripts.
"""

from __future__ import annotations

import errno
import os
import sqlite3
import stat
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote

from sqlalchemy import (
    URL,
    Connection,
    Engine,
    Integer,
    String,
    column,
    create_engine,
    func,
    inspect,
    select,
    table,
)
from sqlalchemy.exc import DBAPIError
from sqlalchemy.pool import NullPool

from db.engine import busy_timeout_ms, describe, make_engine, resolve_url, write_transaction
from db.errors import (
    DatabaseVersionError,
    DbInputError,
    MissingDatabaseError,
    NotAStudyDatabaseError,
    OutdatedDatabaseError,
)
from db.revision import HEAD_REVISION

if TYPE_CHECKING:
    from alembic.config import Config
    from alembic.script import ScriptDirectory

MIGRATIONS_DIR = Path(__file__).parent / "migrations"
VERSION_TABLE = "alembic_version"


class SchemaState(Enum):
    EMPTY = "empty"
    CURRENT = "current"
    OLDER = "older"
    NEWER = "newer"
    FOREIGN = "foreign"


def alembic_config(
    connection: Connection | None = None, version_locations: Sequence[Path] = ()
) -> Config:
    """An Alembic configuration for this package's migrations (no alembic.ini needed).

    `version_locations` adds directories of further revisions (tests use it to stage a
    newer revision than the installed one).
    """
    # lazy: alembic.config costs 0.2 s at start-up
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    cfg.set_main_option("path_separator", "os")
    if version_locations:
        locations = [MIGRATIONS_DIR / "versions", *version_locations]
        cfg.set_main_option("version_locations", os.pathsep.join(str(p) for p in locations))
    cfg.attributes["connection"] = connection
    return cfg


def script_directory(version_locations: Sequence[Path] = ()) -> ScriptDirectory:
    # lazy: alembic.script costs 0.2 s at start-up
    from alembic.script import ScriptDirectory

    return ScriptDirectory.from_config(alembic_config(version_locations=version_locations))


def head_revision(version_locations: Sequence[Path] = ()) -> str:
    head = script_directory(version_locations).get_current_head()
    if head is None:  # pragma: no cover - the package always ships a first revision
        raise RuntimeError("no migration scripts found")
    return head


def current_revision(conn: Connection) -> str | None:
    """The revision stamped in the database, None if it has none (one row at most)."""
    if not inspect(conn).has_table(VERSION_TABLE):
        return None
    rows = conn.execute(select(column("version_num", String)).select_from(table(VERSION_TABLE)))
    revisions = rows.scalars().all()
    if len(revisions) > 1:
        raise DatabaseVersionError(
            f"database holds {len(revisions)} schema revisions {sorted(revisions)}; "
            "expected one (haptic-study's migrations have a single head)"
        )
    return revisions[0] if revisions else None


def schema_state(conn: Connection, version_locations: Sequence[Path] = ()) -> SchemaState:
    revision = current_revision(conn)
    if revision is None:
        tables = set(inspect(conn).get_table_names()) - {VERSION_TABLE}
        return SchemaState.FOREIGN if tables else SchemaState.EMPTY
    if revision == HEAD_REVISION and not version_locations:
        return SchemaState.CURRENT
    scripts = script_directory(version_locations)
    if revision == scripts.get_current_head():
        return SchemaState.CURRENT
    known = {s.revision for s in scripts.walk_revisions()}
    return SchemaState.OLDER if revision in known else SchemaState.NEWER


def upgrade_schema(
    engine: Engine, revision: str = "head", version_locations: Sequence[Path] = ()
) -> tuple[str | None, str]:
    """Upgrade the schema to `revision` under the write lock; return (before, after)."""
    with write_transaction(engine) as conn:
        state = schema_state(conn, version_locations)
        before = current_revision(conn)
        _refuse_unknown(state, before, describe(engine), version_locations)
        from alembic import command

        command.upgrade(alembic_config(conn, version_locations), revision)
        return before, current_revision(conn) or ""


def _refuse_unknown(
    state: SchemaState, revision: str | None, shown: str, version_locations: Sequence[Path]
) -> None:
    if state is SchemaState.NEWER:
        raise DatabaseVersionError(
            f"database {shown} is at schema revision {revision!r}, newer than this "
            f"haptic-study knows (head {head_revision(version_locations)!r}); "
            "expected an older or equal revision: upgrade haptic-study"
        )
    if state is SchemaState.FOREIGN:
        raise NotAStudyDatabaseError(
            f"database {shown} holds tables but no haptic-study schema revision; "
            "expected a study database or an empty one"
        )


def _sqlite_path(url: URL) -> Path | None:
    """The file of an SQLite URL; None for in-memory SQLite and for other backends."""
    if url.get_backend_name() != "sqlite" or url.database in (None, "", ":memory:"):
        return None
    if url.database.startswith("file:") and url.query.get("uri") == "true":
        from urllib.parse import unquote, urlsplit

        return Path(unquote(urlsplit(url.database).path))  # a URI filename's path
    return Path(url.database)


def _cannot_open(shown: str, exc: DBAPIError) -> DbInputError:
    reason = str(exc.orig).strip().splitlines()[0] if exc.orig else str(exc)
    return DbInputError(f"cannot open database {shown}: {reason}")


@contextmanager
def _reading_connection(url: URL) -> Iterator[Connection]:
    """A connection that changes nothing: an SQLite file is opened without the settings
    of `make_engine` (no switch to WAL, which would rewrite the header of a file that
    turns out not to be a study database) and never created (`mode=rw`); one that cannot
    be written is opened read-only and immutable (`readonly_url`). Not `mode=ro` on a
    writable file: a read-only connection to a WAL database leaves its `-wal` and `-shm`
    files behind (it may not delete them), where the last read-write connection removes
    them, so a refused command leaves the folder as it found it. A URL that sets `mode`
    itself (`?mode=ro`) is opened as it says."""

    path = _sqlite_path(url)
    shown = describe(url)
    if path is not None and "mode" in url.query:  # the URL says how (`?mode=ro`)
        engine = make_engine(url)
    elif path is not None and not _writable(path):
        engine = make_engine(readonly_url(path))
    elif path is not None:
        plain = URL.create(
            "sqlite",
            database=f"file:{quote(str(path.absolute()))}",
            query={"mode": "rw", "uri": "true"},
        )
        timeout_s = busy_timeout_ms(url) / 1000
        engine = create_engine(plain, poolclass=NullPool, connect_args={"timeout": timeout_s})
    else:
        engine = make_engine(url)
    try:
        with engine.connect() as conn:
            yield conn
    except DBAPIError as exc:
        raise _cannot_open(shown, exc) from None
    finally:
        engine.dispose()


def _backup_sqlite(path: Path, revision: str | None) -> Path:
    target = path.with_name(f"{path.name}.before-{revision}.bak")
    with sqlite3.connect(path) as src, sqlite3.connect(target) as dst:
        src.backup(dst)
    return target


def open_database(
    db: str | URL | None = None,
    *,
    create: bool = True,
    upgrade: bool = False,
    version_locations: Sequence[Path] = (),
    on_upgrade: Callable[[str | None, str, Path | None], None] | None = None,
    durable: bool = True,
) -> Engine:
    """Open the study database at `db` (URL or SQLite path; see `resolve_url`).

    Creates the schema in an empty database when `create`; upgrades an older one only
    when `upgrade` (`study db upgrade`: an SQLite file is backed up first, and the
    upgrade is reported through `on_upgrade(before, after, backup_path)`), and otherwise
    refuses it with one line naming its revision, so that a command which then fails has
    changed nothing; refuses unknown or foreign schemas with a `DbInputError` before
    anything is written. An SQLite file that cannot be written (read-only media, a
    read-only file or folder) is opened read-only and immutable (`readonly_url`): what
    only reads works, a write fails with a line saying the database is read-only.
    `durable=False`: commits are not synced to the disk one by one
    (`db.engine.make_engine`), for a database thrown away when it is not finished.
    """
    url = resolve_url(db)
    shown = describe(url)
    path = _sqlite_path(url)
    if path is not None:
        check_sqlite_file(path, must_exist=not create)
        _refuse_creating_read_only(url, path)
    state, revision = SchemaState.EMPTY, None
    if path is None or path.exists():
        with _reading_connection(url) as conn:
            state = schema_state(conn, version_locations)
            revision = current_revision(conn)
    _refuse_unknown(state, revision, shown, version_locations)
    if state is SchemaState.EMPTY and not create:
        raise MissingDatabaseError(
            f"database {shown} is empty; expected a study database (run `study init` first)"
        )
    if state is SchemaState.OLDER and not upgrade:
        raise OutdatedDatabaseError(
            f"database {shown} is at schema revision {revision!r}, older than this "
            f"haptic-study's {head_revision(version_locations)!r}; expected the newest: run "
            f"`study db upgrade --db {shown}` first (nothing was changed)"
        )
    if path is not None and path.exists() and not _writable(path):
        if state is not SchemaState.CURRENT:
            raise DbInputError(
                f"database {shown} is read-only and at schema revision {revision!r}; "
                "expected a writable file to create or upgrade its schema"
            )
        return make_engine(readonly_url(path))
    engine = make_engine(url, durable=durable)
    try:
        if state in (SchemaState.EMPTY, SchemaState.OLDER):
            older = state is SchemaState.OLDER
            backup = _backup_sqlite(path, revision) if older and path is not None else None
            before, after = upgrade_schema(engine, version_locations=version_locations)
            if on_upgrade is not None and older:
                on_upgrade(before, after, backup)
    except DBAPIError as exc:
        engine.dispose()
        raise _cannot_open(shown, exc) from None
    except DbInputError:
        engine.dispose()
        raise
    return engine


def _refuse_creating_read_only(url: URL, path: Path) -> None:
    """DbInputError for a missing file that the URL opens read-only: SQLite would make
    an empty file there and then fail to write the schema into it."""
    read_only = url.query.get("mode") == "ro" or url.query.get("immutable") == "1"
    if read_only and not path.exists():
        raise DbInputError(
            f"no study database at {path}, and the URL opens it read-only (?mode=ro or "
            "?immutable=1); expected an existing file, or a URL without them to create one"
        )


def check_sqlite_file(path: Path, *, must_exist: bool) -> None:
    """DbInputError unless `path` can be an SQLite study database: its folder exists, and
    the path is a regular file (a named pipe or a device would block the open or read
    as an empty database), or is missing where `must_exist` is False."""

    if not path.parent.is_dir():
        raise DbInputError(f"folder {path.parent} for database {path} does not exist")
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        if must_exist:
            raise MissingDatabaseError(
                f"no study database at {path}; expected an existing file (run `study init` first)"
            ) from None
        return
    except OSError as exc:
        raise DbInputError(
            f"database {path} cannot be read ({exc.strerror or exc}); expected a readable file"
        ) from None
    if not stat.S_ISREG(mode):
        kind = (
            "a folder"
            if stat.S_ISDIR(mode)
            else "a named pipe"
            if stat.S_ISFIFO(mode)
            else "a device"
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a socket"
            if stat.S_ISSOCK(mode)
            else "no regular file"
        )
        raise DbInputError(f"database {path} is {kind}; expected an SQLite file")


def _writable(path: Path) -> bool:
    """Whether SQLite can write `path` (and its journal and WAL files beside it)."""

    if not (os.access(path, os.W_OK) and os.access(path.parent, os.W_OK)):
        return False
    try:  # a read-only mount lets access() say yes to root
        st = os.statvfs(path)
    except OSError as exc:
        return exc.errno != errno.EROFS
    return not st.f_flag & os.ST_RDONLY


def readonly_url(path: Path) -> URL:
    """SQLite's read-only, immutable open of `path` (`file:PATH?mode=ro&immutable=1`): no
    journal, lock or shared-memory file is made beside it, so a database on read-only
    media opens. Immutable means SQLite assumes no one changes the file meanwhile, true
    of read-only media; a write-ahead log left beside it is not read, so a file whose
    log holds commits is refused instead of shown without them."""
    wal = Path(f"{path}-wal")
    if wal.exists() and wal.stat().st_size > 0:
        raise DbInputError(
            f"database {path} is read-only and its write-ahead log {wal.name} holds commits "
            "not yet in the file; expected a checkpointed file (open it once where it can be "
            "written, or copy it with `study db backup`)"
        )

    return URL.create(
        "sqlite",
        database=f"file:{quote(str(path.absolute()))}",
        query={"mode": "ro", "immutable": "1", "uri": "true"},
    )


@dataclass(frozen=True)
class DatabaseInfo:
    """What `inspect_database` found; `row_counts` maps table name to rows; `samples` is
    the number of stored samples (a chunk row holds up to a second of them)."""

    url: str
    backend: str
    state: SchemaState
    revision: str | None
    head: str
    row_counts: dict[str, int]
    samples: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "state": self.state.value}


def inspect_database(db: str | URL | None = None) -> DatabaseInfo:
    """Describe the database at `db` without creating, upgrading or changing it."""
    url = resolve_url(db)
    path = _sqlite_path(url)
    if path is not None:
        check_sqlite_file(path, must_exist=True)
    with _reading_connection(url) as conn:
        state = schema_state(conn)
        revision = current_revision(conn)
        tables = sorted(set(inspect(conn).get_table_names()) - {"alembic_version"})
        counts = {
            t: int(conn.execute(select(func.count()).select_from(table(t))).scalar_one())
            for t in tables
        }
        samples = counts.get("samples", 0)  # a database from before revision 0005
        if "sample_chunks" in tables:
            stored = select(func.sum(column("n_samples", Integer))).select_from(
                table("sample_chunks")
            )
            samples += int(conn.execute(stored).scalar_one() or 0)
    return DatabaseInfo(
        url=describe(url),
        backend=url.get_backend_name(),
        state=state,
        revision=revision,
        head=head_revision(),
        row_counts=counts,
        samples=samples,
    )


def autogenerate_revision(message: str, rev_id: str) -> None:
    """Developer helper: write the next migration from the models' difference to head.

    Run against a scratch SQLite file brought to head first, then review the script:
    `python -c "from db.migrate import autogenerate_revision as a; a('add x', '0002')"`.
    """
    scratch = Path("autogenerate-scratch.db")
    scratch.unlink(missing_ok=True)
    engine = make_engine(f"sqlite:///{scratch}")
    try:
        upgrade_schema(engine)
        from alembic import command

        with engine.begin() as conn:
            command.revision(
                alembic_config(conn), message=message, autogenerate=True, rev_id=rev_id
            )
    finally:
        engine.dispose()
        scratch.unlink(missing_ok=True)
