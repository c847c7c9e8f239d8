"""`study import-xdf` and `study lsl-config`: the Lab Streaming Layer's files."""

from __future__ import annotations

from pathlib import Path

import click

from db.migrate import open_database
from study.commands.base import (
    StudyCommand,
    bar_progress,
    check_parent_folder,
    db_option,
    progress_bar,
)
from study.errors import StudyInputError


@click.command("import-xdf", cls=StudyCommand)
@click.argument("xdf", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@db_option
def import_xdf(xdf: Path, db_url: str | None) -> None:
    """Store a LabRecorder recording's streams with the trials its markers name.

    The recording must hold the markers a session publishes (`[lsl] publish = true` or
    `study run --lsl`); each other stream's samples between a trial's start and end
    markers are stored with that trial, on its clock. A file without the markers, a
    truncated file, or markers of trials this database does not have: one line, nothing
    stored.

    \b
    Example:
      study import-xdf session.xdf
    """
    # lazy: study.lsl.xdf (with pyarrow, sqlalchemy, numpy) costs 0.2 s at start-up
    from study.lsl.xdf import import_xdf as run_import

    engine = open_database(db_url, create=False)
    try:
        with progress_bar("{task.description}") as bar:
            task = bar.add_task(f"reading {xdf.name}", total=None)
            result = run_import(engine, xdf, bar_progress(bar, task))
    finally:
        engine.dispose()
    click.echo(
        f"{xdf}: {result.samples} samples of {result.streams} stream(s) stored with "
        f"{result.trials} trial(s)"
    )


@click.command("lsl-config", cls=StudyCommand)
@click.argument("path", type=click.Path(dir_okay=False, path_type=Path))
def lsl_config(path: Path) -> None:
    """Write a liblsl configuration that keeps every LSL packet on this machine.

    Point liblsl at it with `export LSLAPICFG=PATH` before `study run --lsl` (a demo on
    one computer, tests, benches). In a lab, write your network's own (liblsl's
    lsl_api.cfg) and name it the same way: `study` loads LSL only with LSLAPICFG set.

    \b
    Example:
      study lsl-config lsl_api.cfg && export LSLAPICFG=$PWD/lsl_api.cfg
    """
    # lazy: study.lsl.config costs 28 ms at start-up
    from study.lsl.config import write_loopback_config

    if path.exists() or path.is_symlink():
        raise StudyInputError(f"{path} exists; expected a new file name")
    check_parent_folder(path)
    try:
        write_loopback_config(path)
    except OSError as exc:
        raise StudyInputError(
            f"{path} cannot be written ({exc.strerror or exc}); expected a writable folder"
        ) from None
    click.echo(f"{path}: liblsl stays on loopback; export LSLAPICFG={path.resolve()}")
