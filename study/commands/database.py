"""`study db ...`: create, upgrade, describe, check and back up the study database."""

from __future__ import annotations

import json
from pathlib import Path

import click

from db.engine import describe
from db.migrate import head_revision, inspect_database, open_database
from study.commands.base import StudyGroup, db_option
from study.errors import StudyInputError
from teleop_core.files import replace_durably


@click.group("db", cls=StudyGroup)
def database() -> None:
    """Create, upgrade, describe, check and back up the study database.

    \b
    Example:
      study db info
    """


@database.command("upgrade")
@db_option
def upgrade_cmd(db_url: str | None) -> None:
    """Bring the database to the newest schema (creating it if it is empty).

    An SQLite file is copied to NAME.before-REVISION.bak before it is upgraded.

    \b
    Example:
      study db upgrade --db old-study.db
    """
    upgraded: list[str] = []

    def report(before: str | None, after: str, backup: Path | None) -> None:
        saved = f"; the old file is kept as {backup}" if backup else ""
        upgraded.append(f"upgraded from revision {before} to {after}{saved}")

    engine = open_database(db_url, upgrade=True, on_upgrade=report)
    where = describe(engine)
    engine.dispose()
    click.echo(f"{where}: {upgraded[0] if upgraded else f'at revision {head_revision()} (newest)'}")


@database.command("info")
@db_option
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
def info_cmd(db_url: str | None, as_json: bool) -> None:
    """Describe the database without changing it: schema revision and rows per table.

    \b
    Example:
      study db info --db lab.db
    """
    info = inspect_database(db_url)
    if as_json:
        click.echo(json.dumps(info.to_dict(), indent=2))
        return
    click.echo(f"database: {info.url}")
    click.echo(f"schema:   revision {info.revision} ({info.state.value}; newest is {info.head})")
    for name, rows in info.row_counts.items():
        click.echo(f"  {name:<16} {rows:>10,} rows")
    click.echo(f"samples:  {info.samples:,}")


@database.command("check")
@db_option
def check_cmd(db_url: str | None) -> None:
    """Check the database's integrity, in one line (never writes).

    SQLite: PRAGMA integrity_check and foreign_key_check; PostgreSQL: every table's
    rows counted and no row pointing at a missing one. Both: the schema at the newest
    revision. Exit status 1 when problems are found.

    \b
    Example:
      study db check --db lab.db
    """
    # lazy: db.maintenance costs 4 ms at start-up
    from db.maintenance import check_database

    engine = open_database(db_url, create=False)
    try:
        result = check_database(engine)
    finally:
        engine.dispose()
    click.echo(result.line())
    if not result.ok:
        raise click.exceptions.Exit(1)


@database.command("backup")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("backups"),
    show_default=True,
    help="Folder of the copies (made if missing); each copy is NAME-YYYYMMDDTHHMMSSZ.db.",
)
@db_option
def backup_cmd(out_dir: Path, db_url: str | None) -> None:
    """End of day: check the database, copy it to one SQLite file, check the copy.

    The copy is one consistent snapshot while sessions run (SQLite: VACUUM INTO;
    PostgreSQL: every table in one REPEATABLE READ transaction, no pg_dump needed) and
    opens with `study tui --db COPY`. One line: the check, the copy, its size and
    SHA-256. Exit status 1 (and no copy) when the database has problems.

    \b
    Example:
      study db backup --out backups/
    """
    # lazy: db.maintenance costs 4 ms at start-up
    from db.maintenance import backup_database

    engine = open_database(db_url, create=False)
    try:
        result = backup_database(engine, out_dir, replace_file=replace_durably)
    except OSError as exc:
        raise StudyInputError(
            f"backup to {out_dir} failed: {exc.strerror or exc}; expected a writable folder "
            "with free space (the database is unchanged and no copy was kept)"
        ) from exc
    finally:
        engine.dispose()
    click.echo(result.line())
    if not (result.source.ok and result.copy.ok):
        raise click.exceptions.Exit(1)
