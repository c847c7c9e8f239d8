"""`study import` and `study export`: tidy CSV (or Parquet) in and out."""

from __future__ import annotations

from pathlib import Path

import click

from db.migrate import open_database
from study.commands.base import StudyCommand, db_option


@click.command("import", cls=StudyCommand)
@click.option(
    "--trials", "trials_csv", required=True, type=click.Path(dir_okay=False, path_type=Path)
)
@click.option("--tlx", "tlx_csv", type=click.Path(dir_okay=False, path_type=Path))
@db_option
def import_cmd(trials_csv: Path, tlx_csv: Path | None, db_url: str | None) -> None:
    """Import trial summaries (and NASA-TLX) collected elsewhere: all rows or none."""
    from study.protocol.exchange import import_data  # pandas: only when a command runs

    engine = open_database(db_url, create=False)
    try:
        n_trials, n_tlx = import_data(engine, trials_csv, tlx_csv)
    finally:
        engine.dispose()
    click.echo(f"imported {n_trials} trials and {n_tlx} questionnaires")


@click.command("export", cls=StudyCommand)
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--format", "fmt", type=click.Choice(["csv", "parquet"]), default="csv", show_default=True
)
@click.option("--samples", is_flag=True, help="Also write every sample of every measured trial.")
@db_option
def export_cmd(out_dir: Path, fmt: str, samples: bool, db_url: str | None) -> None:
    """Export trials, TLX (and samples) with a codebook, for other tools."""
    from study.protocol.exchange import export_data

    engine = open_database(db_url, create=False)
    try:
        written = export_data(engine, out_dir, fmt, samples)
    finally:
        engine.dispose()
    for path in written:
        click.echo(str(path))
