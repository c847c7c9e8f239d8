"""`study figures` and `study demo`."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from db.errors import MissingDatabaseError
from db.migrate import open_database
from study.analysis.source import DRIVERS
from study.commands.base import (
    SEED,
    StudyCommand,
    db_option,
    load_participants,
    participants_option,
    progress_status,
    status_progress,
)
from study.commands.typed import comma_list
from study.errors import StudyInputError

if TYPE_CHECKING:
    from study.protocol.parallel import Workers

FORMATS = ("pdf", "svg", "png")


def _formats(text: str) -> list[str]:

    return comma_list("--format", text, tuple(FORMATS))


@click.command("figures", cls=StudyCommand)
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for the figures (created if its parent exists).",
)
@click.option(
    "--format",
    "formats",
    default="pdf,svg,png",
    show_default=True,
    help="Comma-separated: pdf, svg, png (300 dpi).",
)
@click.option(
    "--width",
    type=click.Choice(["single", "double"]),
    default="double",
    show_default=True,
    help="IEEE column width: 3.5 in or 7.16 in.",
)
@click.option(
    "--driver",
    type=click.Choice(DRIVERS),
    default=None,
    help="Only trials of this driver [default: all; a simulated share is written on every figure].",
)
@click.option(
    "--task", default=None, help="Only this task's figures (e.g. lcca) [default: one set per task]."
)
@click.option(
    "--tlx-score",
    type=click.Choice(["weighted", "raw"]),
    default="weighted",
    show_default=True,
    help="The NASA-TLX score of Fig. 12's TLX panel (raw where no questionnaire has the "
    "pairwise choices); its y-label names it.",
)
@db_option
def figures(
    out_dir: Path,
    formats: str,
    width: str,
    driver: str | None,
    task: str | None,
    tlx_score: str,
    db_url: str | None,
) -> None:
    """Draw the paper's figures, one set per task: group comparison, force traces,
    NASA-TLX profile (FIGURE_TASK.pdf, e.g. fig12_groups_lcca.pdf), and their captions
    in captions.md beside them.

    Fig. 12 (per group, VO vs HV, marks from that task's Holm-corrected tests, no mark
    where no test was run), Fig. 9 (a VO and an HV trial's forces) and the TLX profile
    per group. Every figure passes the figure check (text >= 8 pt, no overlapping text,
    marks equal to the reported p) before any is written.

    \b
    Example:
      study figures --out figures/ --width single
    """
    # lazy: study.analysis.paper (with scipy, pandas, pyarrow) costs 1.4 s at start-up
    from study.analysis.paper import write_figures

    chosen = _formats(formats)
    engine = open_database(db_url, create=False)
    try:
        for path in write_figures(engine, out_dir, chosen, width, driver, task, tlx_score):
            click.echo(str(path))
    finally:
        engine.dispose()


def _analyse_demo(db_url: str, out_dir: Path, workers: Workers) -> None:
    """The demo's analysis and figures; a paper needs both IEEE widths: double column in
    FIGURES, single in FIGURES/single, drawn by a session worker meanwhile."""
    # lazy: study.analysis.frames (with pandas, pyarrow, numpy) costs 0.3 s at start-up
    from study.analysis.frames import participant_means, tlx_frame, trial_frame

    # lazy: study.analysis.paper (with scipy, pandas, pyarrow) costs 1.4 s at start-up
    from study.analysis.paper import write_figures, write_figures_at

    # lazy: study.analysis.report (with numpy) costs 0.1 s at start-up
    from study.analysis.report import write

    # lazy: study.analysis.stats (with numpy) costs 74 ms at start-up
    from study.analysis.stats import analyze

    single = workers.submit(write_figures_at, db_url, out_dir / "figures" / "single", "single")
    engine = open_database(db_url, create=False)
    try:
        trials, tlx = trial_frame(engine), tlx_frame(engine)
        result = analyze(trials, participant_means(trials, tlx))
        write(result, out_dir / "analysis", None)
        write_figures(engine, out_dir / "figures")
    finally:
        engine.dispose()
    single.result()


def _check_resumable(db_url: str, seed: int, quick: bool) -> bool:
    """Whether `db_url` holds an incomplete demo that this run continues (False: a new
    database); StudyInputError for anything else there (`check_resumable`)."""
    # lazy: study.protocol.demo (with pandas, pyarrow, sqlalchemy) costs 0.4 s at start-up
    from study.protocol.demo import check_resumable

    try:
        engine = open_database(db_url, create=False)
    except MissingDatabaseError:
        return False
    try:
        check_resumable(engine, seed, quick)
    except StudyInputError as exc:
        raise StudyInputError(f"{db_url}: {exc}") from None
    finally:
        engine.dispose()
    return True


@click.command("demo", cls=StudyCommand)
@click.option(
    "--out",
    "out_dir",
    default=Path("demo"),
    show_default=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for the demo's database, analysis/ and figures/ (a new one).",
)
@click.option(
    "--db",
    "db_url",
    default=None,
    metavar="URL",
    help="Database for the demo study [default: OUT/demo.db].",
)
@click.option(
    "--seed",
    type=SEED,
    default=1,
    show_default=True,
    help="Seed of the simulated people and trials.",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=2,
    show_default=True,
    help="Processes that run the sessions side by side.",
)
@click.option("--quick", is_flag=True, help="2 participants per group, one trial per block.")
@participants_option
def demo(
    out_dir: Path,
    db_url: str | None,
    seed: int,
    jobs: int,
    quick: bool,
    participants_path: Path | None,
) -> None:
    """Simulate the paper's whole study (20/8/8, VO and HV, NASA-TLX) and analyse it.

    A demo stopped halfway (killed, a power cut) is continued by the same command in the
    same folder: its sessions go on where they stopped. Until it completes, its
    database says it is an incomplete demo (`study schedule`).

    \b
    Example:
      study demo --out demo/ --seed 1
    """
    # lazy: study.protocol.parallel costs 7 ms at start-up
    from study.protocol.parallel import start_workers

    start = time.monotonic()
    model = load_participants(participants_path)
    if db_url is None:
        out_dir.mkdir(parents=True, exist_ok=True)
        db_url = str(out_dir / "demo.db")
    resumed = _check_resumable(db_url, seed, quick)
    if resumed:
        click.echo(f"continuing the incomplete demo in {db_url}", err=True)
    with progress_status("demo study") as status:

        def notice(message: str) -> None:
            status.console.print(f"study demo: {message}", markup=False)

        model_path = str(participants_path) if model is not None else None
        # the workers start first: their start runs beside this process's imports and the
        # creation of the study
        with start_workers(
            db_url, jobs, participants=model_path, notice=notice, durable=False
        ) as workers:
            from study.protocol.demo import run_demo

            run_demo(
                db_url,
                seed,
                jobs,
                progress=status_progress(status),
                quick=quick,
                participants=model_path,
                notice=notice,
                workers=workers,
            )
            status.update("analysis and figures")
            _analyse_demo(db_url, out_dir, workers)
    if model is not None:
        click.echo(f"simulated participants drawn from the {model.label()}")
    click.echo(
        f"SIMULATED demo study (every participant, trial and questionnaire simulated) "
        f"in {db_url}; analysis in {out_dir / 'analysis'}; figures in "
        f"{out_dir / 'figures'} (double column) and {out_dir / 'figures' / 'single'} "
        f"(single column) ({time.monotonic() - start:.0f} s)"
    )
