"""`study analyze`: the statistics of the stored study."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from db.plain import plain_sqlite
from study.analysis.source import DRIVERS
from study.commands.base import StudyCommand, check_parent_folder, db_option
from study.errors import StudyInputError

if TYPE_CHECKING:  # pandas only where the covariate needs it
    import pandas as pd

    from study.analysis.paired import EquivalenceBounds

Row = dict[str, Any]
DDF_NAMES = {"satterthwaite": "Satterthwaite", "kenward-roger": "Kenward-Roger"}
"""`--ddf`'s values and the mixed model's names of them (`stats_lmm.DDF_METHODS`)."""


@click.command("analyze", cls=StudyCommand)
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for methods.md, the tables and analysis.json (created if its parent exists).",
)
@click.option("--task", default=None, help="Only this task (e.g. lcca) [default: all].")
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the JSON here [default: OUT/analysis.json].",
)
@click.option(
    "--driver",
    type=click.Choice(DRIVERS),
    default=None,
    help="Only trials of this driver (and their blocks' questionnaires) "
    "[default: all, their mix stated in every output].",
)
@click.option(
    "--ss-type",
    type=click.Choice(["2", "3"]),
    default="2",
    show_default=True,
    help="Sums of squares of the mixed ANOVA: Type II (participant-weighted "
    "condition effect) or Type III (afex's default).",
)
@click.option(
    "--ddf",
    type=click.Choice(["satterthwaite", "kenward-roger"]),
    default="satterthwaite",
    show_default=True,
    help="Degrees of freedom of the mixed model's t tests (as lmerTest's ddf); "
    "analysis.json and methods.md name the one used.",
)
@click.option(
    "--covariate",
    default=None,
    metavar="NAME",
    help="A probe (or the trait it tells, e.g. force_threshold) whose estimate per "
    "participant enters the mixed model as a covariate; adds "
    "covariate_NAME.csv and ancova_NAME.csv.",
)
@db_option
def analyze(
    out_dir: Path,
    task: str | None,
    json_path: Path | None,
    driver: str | None,
    ss_type: str,
    ddf: str,
    covariate: str | None,
    db_url: str | None,
) -> None:
    """Per-group VO vs HV tests, the mixed ANOVA and the mixed model: methods.md, tables
    (CSV, Markdown, LaTeX; one set per task too when there are several) and JSON.

    Every output counts the trials by driver (simulated, keyboard, hardware, imported) and
    says so when any is simulated.

    \b
    Example:
      study analyze --out results/
    """
    # The models' matrices have hundreds of rows: OpenBLAS's worker threads would only
    # spin beside the one that computes (a sixth of the command's CPU time). Set before
    # numpy loads; a value the user set stands.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    # lazy: study.analysis.means costs 9 ms at start-up
    from study.analysis.means import (
        choiceless_notes,
        participant_mean_rows,
        restrict_rows,
        tlx_measure_rows,
    )

    # lazy: study.analysis.report (with numpy) costs 0.1 s at start-up
    from study.analysis.report import write

    # lazy: study.analysis.stats (with numpy) costs 84 ms at start-up
    from study.analysis.stats import analyze_rows

    if json_path is not None:
        check_parent_folder(json_path)
    start = time.monotonic()
    trials, tlx, withdrawn, bounds = _usable_rows(db_url)
    if covariate is not None:
        probe_trials, trait, values = _probe_covariate(db_url, covariate)
    if task is not None:
        trials, tlx = _only_task(trials, tlx, task)
    if not trials and not tlx:
        raise StudyInputError("the database holds no completed trials or questionnaires to analyse")
    trials, tlx = restrict_rows(trials, tlx, driver)
    withdrawn = [
        n for n in [*withdrawn, *choiceless_notes(tlx)] if task is None or n.startswith(f"{task}/")
    ]
    long = participant_mean_rows(trials, tlx_measure_rows(tlx))
    result = analyze_rows(
        trials,
        long,
        ss_type=int(ss_type),
        withdrawn=withdrawn,
        ddf=DDF_NAMES[ddf],
        bounds=bounds,
    )
    written = write(result, out_dir, json_path)
    for path in written:
        click.echo(str(path))
    if covariate is not None:
        from study.protocol.trial_table import trial_table

        _echo_probe_drivers(covariate, probe_trials)
        _covariate(trial_table(trials), values, trait, out_dir)
    if result.source.note:
        click.echo(result.source.note)
    click.echo(
        f"{len(result.comparison_rows)} comparisons, {len(result.exclusions)} exclusions, "
        f"{len(result.warnings)} notes, in {time.monotonic() - start:.1f} s"
    )


def _usable_rows(
    db_url: str | None,
) -> tuple[list[Row], list[Row], list[str], EquivalenceBounds]:
    """The trials and questionnaires to analyse (`_read`) without the withdrawn
    participants and the trials marked invalid, the notes saying who and which were
    left out, and the design's equivalence bounds."""
    # lazy: study.analysis.means costs 9 ms at start-up
    from study.analysis.means import without_invalid_rows, without_withdrawn_rows

    # lazy: study.analysis.paired (with numpy) costs 64 ms at start-up
    from study.analysis.paired import EquivalenceBounds

    trials, tlx, withdrawn_codes, invalid, analysis = _read(db_url)
    trials, tlx, withdrawn = without_withdrawn_rows(withdrawn_codes, trials, tlx)
    trials, invalid_notes = without_invalid_rows(invalid, trials)
    withdrawn += invalid_notes
    bounds = EquivalenceBounds(
        analysis.get("equivalence_fraction"), analysis.get("equivalence_bounds", {})
    )
    return trials, tlx, withdrawn, bounds


def _probe_covariate(db_url: str | None, covariate: str) -> tuple[pd.DataFrame, str, pd.Series]:
    """The stored probe trials, and the trait `covariate` names with its estimate per
    participant (`covariate_values`)."""
    # lazy: db.migrate (with sqlalchemy) costs 0.3 s at start-up
    from db.migrate import open_database

    # lazy: study.analysis.covariate (with scipy, statsmodels, pandas) costs 1.2 s at start-up
    from study.analysis.covariate import covariate_values

    # lazy: study.probes.store (with pandas, pyarrow, sqlalchemy) costs 0.7 s at start-up
    from study.probes.store import probe_frame

    engine = open_database(db_url, create=False)
    try:
        probe_trials = probe_frame(engine)
    finally:
        engine.dispose()
    trait, values = covariate_values(probe_trials, covariate)
    return probe_trials, trait, values


def _only_task(trials: list[Row], tlx: list[Row], task: str) -> tuple[list[Row], list[Row]]:
    """The trials and questionnaires of `task`; a task without either is bad input."""
    known = {r["task"] for r in trials} | {r["task"] for r in tlx}
    if task not in known:
        raise StudyInputError(
            f"no data for task {task!r}; expected one of "
            f"{', '.join(sorted(known)) or 'none stored'}"
        )
    return [r for r in trials if r["task"] == task], [r for r in tlx if r["task"] == task]


def _echo_probe_drivers(covariate: str, probe_trials: pd.DataFrame) -> None:
    """Print the probe trials' count by driver, saying so when any is simulated."""
    drivers = probe_trials["driver"].value_counts().to_dict()
    click.echo(
        f"covariate {covariate}: probe trials by driver: "
        + ", ".join(f"{d} {n}" for d, n in sorted(drivers.items()))
        + (" (SIMULATED participants' answers)" if "simulated" in drivers else "")
    )


def _read(db_url: str | None) -> tuple[list[dict], list[dict], dict[str, str], dict, dict]:
    """The trials, questionnaires, withdrawn participants and trials marked invalid
    (`study_rows`): from an
    SQLite file at the current schema through `sqlite3` alone (`db.plain`), otherwise
    through `open_database` (which upgrades an older schema and serves PostgreSQL)."""
    # lazy: study.protocol.study_rows costs 8 ms at start-up
    from study.protocol.study_rows import (
        design_analysis,
        invalid_rows,
        tlx_rows,
        trial_rows,
        withdrawn_rows,
    )

    def rows(conn: Any) -> tuple[list[dict], list[dict], dict[str, str], dict, dict]:
        return (
            trial_rows(conn),
            tlx_rows(conn),
            withdrawn_rows(conn),
            invalid_rows(conn),
            design_analysis(conn),
        )

    conn = plain_sqlite(db_url)
    if conn is not None:
        try:
            return rows(conn)
        finally:
            conn.close()
    # lazy: db.migrate (with sqlalchemy) costs 0.3 s at start-up
    from db.migrate import open_database

    # lazy: study.protocol.trial_table (with pandas, pyarrow, sqlalchemy) costs 0.5 s at start-up
    from study.protocol.trial_table import driver_connection

    engine = open_database(db_url, create=False)
    try:
        with driver_connection(engine) as conn:
            return rows(conn)
    finally:
        engine.dispose()


def _covariate(trials, values, trait: str, out_dir: Path) -> None:
    """The covariate's mixed model and ANCOVA-style table: written, and the table printed."""
    # lazy: study.analysis.covariate (with scipy, statsmodels, pandas) costs 1.2 s at start-up
    from study.analysis.covariate import covariate_model

    # lazy: study.protocol.tasks costs 6 ms at start-up
    from study.protocol.tasks import get_task

    # lazy: teleop_core.files costs 5 ms at start-up
    from teleop_core.files import atomic_path

    measures = {t: get_task(t).analysed_measures for t in trials["task"].unique()}
    lmm, ancova, notes = covariate_model(trials, values, measures, trait)
    for name, frame in ((f"covariate_{trait}.csv", lmm), (f"ancova_{trait}.csv", ancova)):
        with atomic_path(out_dir / name) as tmp:
            frame.to_csv(tmp, index=False)
        click.echo(str(out_dir / name))
    for note in notes:
        click.echo(note)
    for r in ancova.itertuples():
        click.echo(
            f"{r.task}/{r.measure}: {r.effect} {r.estimate:.4g} "
            f"(95 % {r.ci_low:.4g} to {r.ci_high:.4g}, p = {r.p:.3g}, n = {r.participants})"
        )
