"""`study import` and `study export`: tidy CSV (or Parquet) in and out."""

from __future__ import annotations

from pathlib import Path

import click

from db.migrate import open_database
from study.commands.base import (
    StudyCommand,
    actor_option,
    bar_progress,
    db_option,
    file_option,
    opened_database,
    progress_bar,
)
from study.errors import StudyInputError


@click.command("import", cls=StudyCommand)
@file_option(
    "--trials", "trials_csv", "Trial summaries CSV (the columns of `study export`'s trials.csv)."
)
@click.option(
    "--tlx",
    "tlx_csv",
    type=click.Path(dir_okay=False, path_type=Path),
    help="NASA-TLX CSV (the columns of `study export`'s tlx.csv) [default: none].",
)
@click.option(
    "--probes",
    "probes_csv",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Probe trials (probe_trials.csv of `study export`).",
)
@click.option(
    "--enrol-new",
    is_flag=True,
    help="Enrol the participants the file is the first to name (without it, a code the "
    "study does not have is refused).",
)
@actor_option
@db_option
def import_cmd(
    trials_csv: Path,
    tlx_csv: Path | None,
    probes_csv: Path | None,
    enrol_new: bool,
    actor: str | None,
    db_url: str | None,
) -> None:
    """Import trial summaries (and NASA-TLX, probe trials) collected elsewhere: all rows or
    none.

    \b
    Example:
      study import --trials trials.csv --tlx tlx.csv
    """
    from study.protocol.exchange import import_data  # pandas: only when a command runs

    with opened_database(db_url) as engine:
        probes = None
        if probes_csv is not None:
            # every probe row checked, and its participants known from the study or the
            # trials file, before anything is written
            from study.probes.exchange import (
                check_not_stored,
                check_participants,
                known_codes,
                read_probe_file,
            )

            probes = read_probe_file(probes_csv)
            check_participants(probes, known_codes(engine, trials_csv), probes_csv)
            check_not_stored(engine, probes, probes_csv)
        n_trials, n_tlx = import_data(engine, trials_csv, tlx_csv, actor, enrol_new=enrol_new)
        n_probes = 0
        if probes_csv is not None and probes is not None:
            from study.probes.exchange import import_probes

            n_probes = import_probes(engine, probes_csv, probes)
    click.echo(
        f"imported {n_trials} trials and {n_tlx} questionnaires"
        + (f" and {n_probes} probe trials" if probes_csv is not None else "")
    )


@click.command("export", cls=StudyCommand)
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for the exported files and codebook.csv (created if its parent exists).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["csv", "parquet"]),
    default="csv",
    show_default=True,
    help="File format of the tables.",
)
@click.option("--samples", is_flag=True, help="Also write every sample of every measured trial.")
@click.option(
    "--participant",
    "participants",
    multiple=True,
    metavar="CODE",
    help="Samples of this participant only (repeat for several).",
)
@click.option(
    "--task", "tasks", multiple=True, metavar="NAME", help="Samples of this task only (repeatable)."
)
@click.option(
    "--condition",
    "conditions",
    multiple=True,
    metavar="NAME",
    help="Samples of this condition only (repeatable).",
)
@click.option(
    "--trial",
    "trials",
    multiple=True,
    type=click.IntRange(min=1),
    metavar="N",
    help="Samples of measured trial N of each block only, from 1 (repeatable).",
)
@click.option(
    "--from-s",
    type=click.FloatRange(min=0),
    default=None,
    help="Samples at or after this time since the trial started, s.",
)
@click.option(
    "--to-s",
    type=click.FloatRange(min=0),
    default=None,
    help="Samples before this time since the trial started, s.",
)
@click.option(
    "--per-trial",
    is_flag=True,
    help="One samples file per trial in OUT/samples/; a rerun skips the files already "
    "complete (resumes an interrupted export).",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=None,
    help="Threads reading samples [default: one per CPU, at most 4].",
)
@db_option
def export_cmd(
    out_dir: Path,
    fmt: str,
    samples: bool,
    participants: tuple[str, ...],
    tasks: tuple[str, ...],
    conditions: tuple[str, ...],
    trials: tuple[int, ...],
    from_s: float | None,
    to_s: float | None,
    per_trial: bool,
    jobs: int | None,
    db_url: str | None,
) -> None:
    """Export trials, TLX (and samples) with a codebook, for other tools.

    Samples stream in bounded memory; --participant, --task, --condition, --trial,
    --from-s and --to-s restrict the samples (not the trials and TLX files).

    \b
    Example:
      study export --out export/ --samples
    """
    # lazy: study.protocol.export (with pandas, pyarrow, sqlalchemy) costs 0.5 s at start-up
    from study.protocol.export import export_data

    # lazy: study.protocol.sample_export (with pandas, pyarrow, sqlalchemy) costs 0.5 s at start-up
    from study.protocol.sample_export import SampleSelection

    selection = SampleSelection(participants, tasks, conditions, trials, from_s, to_s)
    engine = open_database(db_url, create=False)
    created = not out_dir.exists()
    try:
        with progress_bar() as bar:
            task = bar.add_task("exporting samples (trials)", total=None)
            written = export_data(
                engine,
                out_dir,
                fmt,
                samples,
                selection,
                per_trial=per_trial,
                workers=jobs,
                progress=bar_progress(bar, task, describe=False),
            )
    except BaseException as exc:
        # nothing half-written: a folder this command made and left empty goes again
        if created and out_dir.is_dir() and not any(out_dir.iterdir()):
            out_dir.rmdir()
        if isinstance(exc, OSError):
            raise StudyInputError(
                f"export to {out_dir} failed: {exc.strerror or exc}; expected a writable "
                "folder with free space (the files already there are unchanged)"
            ) from exc
        raise
    finally:
        engine.dispose()
    for path in written:
        click.echo(str(path))
