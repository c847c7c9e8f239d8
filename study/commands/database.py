"""`study db ...`: create, upgrade and describe the study database."""

from __future__ import annotations

import json
from pathlib import Path

import click

from db.engine import describe
from db.migrate import head_revision, inspect_database, open_database
from study.commands.base import StudyGroup, db_option


@click.group("db", cls=StudyGroup)
def database() -> None:
    """Create, upgrade and describe the study database."""


@database.command("upgrade")
@db_option
def upgrade_cmd(db_url: str | None) -> None:
    """Bring the database to the newest schema (creating it if it is empty).

    An SQLite file is copied to NAME.before-REVISION.bak before it is upgraded.
    """
    upgraded: list[str] = []

    def report(before: str | None, after: str, backup: Path | None) -> None:
        saved = f"; the old file is kept as {backup}" if backup else ""
        upgraded.append(f"upgraded from revision {before} to {after}{saved}")

    engine = open_database(db_url, on_upgrade=report)
    where = describe(engine)
    engine.dispose()
    click.echo(f"{where}: {upgraded[0] if upgraded else f'at revision {head_revision()} (newest)'}")


@database.command("info")
@db_option
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
def info_cmd(db_url: str | None, as_json: bool) -> None:
    """Describe the database without changing it: schema revision and rows per table."""
    info = inspect_database(db_url)
    if as_json:
        click.echo(json.dumps(info.to_dict(), indent=2))
        return
    click.echo(f"database: {info.url}")
    click.echo(f"schema:   revision {info.revision} ({info.state.value}; newest is {info.head})")
    for name, rows in info.row_counts.items():
        click.echo(f"  {name:<16} {rows:>10,} rows")
    click.echo(f"samples:  {info.samples:,}")
