"""`study example-data`: the files the tutorials use, copied into a folder of the user's."""

from __future__ import annotations

from pathlib import Path

import click

from study.commands.base import StudyCommand


@click.command("example-data", cls=StudyCommand)
@click.argument("folder", type=click.Path(file_okay=False, path_type=Path))
def example_data(folder: Path) -> None:
    """Copy the tutorials' example data into FOLDER (created if its parent exists).

    FOLDER receives `emps/`, a measured drive recording (the EMPS benchmark, with its
    citation) for the calibration tutorial, and `probe_task/`, the worked example of
    a lab's own task, a package to install with pip. An existing `emps/` or
    `probe_task/` in FOLDER is left alone and nothing is written.

    \b
    Example:
      study example-data data/ && pip install data/probe_task
    """
    # lazy: study.example_data costs 6 ms at start-up
    from study.example_data import copy_to

    for target in copy_to(folder):
        click.echo(f"{target}/")
