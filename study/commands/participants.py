"""`study participants fit`: simulated participants fitted to a study's trials.

`study participant` (singular) enrols people; this group is about the simulated ones.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from study.analysis.participant_fit import WEAK_TRAITS
from study.commands.base import (
    SEED,
    StudyGroup,
    check_parent_folder,
    count_option,
    db_option,
    file_option,
    opened_database,
    progress_bar,
)
from study.errors import StudyInputError

if TYPE_CHECKING:
    from rich.progress import TaskID

    from study.analysis.participant_fit.fit import FitResult


@click.group("participants", cls=StudyGroup)
def participants() -> None:
    """Simulated participants: fit their trait distributions to a study's trials.

    \b
    Example:
      study participants fit --out MODEL.json
    """


@participants.command("fit")
@db_option
@click.option(
    "--task",
    default="lcca",
    show_default=True,
    help="The task whose trials are fitted (lcca, notes, or a registered one).",
)
@file_option("--out", "out_path", "MODEL.json to write; the figure goes beside it (MODEL.png).")
@count_option(
    "--design", 320, "Trait settings the emulator is built from.", minimum=16, dest="n_design"
)
@count_option("--repeats", 2, "Trials per condition at each setting.")
@count_option(
    "--check",
    24,
    "People per group simulated from the fit for the summaries and checks.",
    minimum=4,
    dest="n_check",
)
@click.option(
    "--bootstrap",
    type=click.IntRange(min=20),
    default=100,
    show_default=True,
    help="Bootstrap resamples of the people for the intervals.",
)
@click.option(
    "--weak-traits",
    type=click.Choice(WEAK_TRAITS),
    default="prior",
    show_default=True,
    help="The traits the data tell weakly: held at the hand-set "
    "profile, or fitted with their group mean under the profile's prior.",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=2,
    show_default=True,
    help="Processes that run the simulations side by side.",
)
@click.option(
    "--seed", type=SEED, default=0, show_default=True, help="Seed of the simulations and resamples."
)
def fit(
    db_url: str | None,
    task: str,
    out_path: Path,
    n_design: int,
    repeats: int,
    n_check: int,
    bootstrap: int,
    weak_traits: str,
    jobs: int,
    seed: int,
) -> None:
    """Fit each experience group's trait distributions to the database's completed trials
    (a hierarchical model on an emulator of the measures and the samples' behavioural
    features); write MODEL.json and MODEL.png, print the
    observed vs simulated summaries and one line on what the participants lack.

    \b
    Example:
      study participants fit --out MODEL.json
    """
    # lazy: db.engine (with sqlalchemy) costs 0.2 s at start-up
    from db.engine import describe, resolve_url

    # lazy: study.analysis.participant_fit.fit (with scipy, sklearn, pandas) costs 1.7 s at start-up
    from study.analysis.participant_fit.fit import FitSettings, fit_study

    # lazy: study.protocol.tasks costs 6 ms at start-up
    from study.protocol.tasks import get_task

    get_task(task)  # an unknown task: one line before anything runs
    check_parent_folder(out_path)
    if out_path.suffix != ".json":
        raise StudyInputError(f"--out {out_path}; expected a file name ending in .json")
    settings = FitSettings(
        design=n_design,
        repeats=repeats,
        check=n_check,
        bootstrap=bootstrap,
        jobs=jobs,
        seed=seed,
        weak_traits=weak_traits,
    )
    start = time.monotonic()
    with opened_database(db_url) as engine, progress_bar() as bar:
        bars: dict[str, TaskID] = {}

        def progress(step: str, k: int = 0, n: int = 0) -> None:
            if step not in bars:
                bars[step] = bar.add_task(
                    {
                        "samples": "reading the trials' samples",
                        "emulator": "simulating the emulator's design",
                        "validating": "checking the emulator on held-out settings",
                        "effects": "looking for participant effects",
                        "fitting": "fitting the groups",
                        "checking": "simulating people from the fit",
                    }[step],
                    total=n,
                )
            bar.update(bars[step], completed=k, total=n)

        result = fit_study(engine, task, settings, describe(resolve_url(db_url)), progress)
    table = result.table
    model = _write(out_path, result, round(time.monotonic() - start, 1))
    _print(model, table)
    click.echo(model["probes"]["line"])
    click.echo(model["lacks"]["line"])
    click.echo(model["effects_line"])
    click.echo(model["emulator_check"]["line"])
    click.echo(
        f"model: {out_path}; figure: {out_path.with_suffix('.png')} ({model['seconds']:.0f} s)"
    )


def _write(out_path: Path, result: FitResult, seconds: float) -> dict:
    """MODEL.png, then MODEL.json (by the fit's result), each written whole or not at all."""
    # lazy: study.analysis.participant_fit.figure costs 2.1 s at start-up
    from study.analysis.participant_fit.figure import fit_figure

    source = result.data.source
    note = (
        f"Fitted to {source.upper()} trials "
        f"({result.data.counts['note'] or 'measured'}); "
        "simulated marks are SIMULATED people drawn from the fitted model"
    )
    png = out_path.with_suffix(".png")
    # lazy: teleop_core.files costs 5 ms at start-up
    from teleop_core.files import atomic_path

    with atomic_path(png, suffix=".png") as tmp_png:
        fit_figure(result.table, note).savefig(tmp_png, dpi=200)
    return result.write(out_path, {"seconds": seconds})


def _print(model: dict, table: object) -> None:
    # lazy: study.analysis.participant_fit.fit (with scipy, sklearn, pandas) costs 1.7 s at start-up
    from study.analysis.participant_fit.fit import dropped_text

    fits = model["fit"]
    click.echo(
        f"{model['task']}: fitted to {model['fitted_from']['participants']} participants' "
        f"{model['fitted_from']['trials']} trials ({model['data_source']})"
    )
    features = model["features"]
    click.echo(
        f"moments: the measures and {len(features['names'])} sample features "
        f"({features['trials_with_samples']} of {model['fitted_from']['trials']} trials "
        "with samples)"
        + (f"; {dropped_text(features['dropped'])}" if features.get("dropped") else "")
        if features["names"]
        else f"moments: {features['note']}"
    )
    click.echo(
        f"identifiable from the moments: {', '.join(model['identifiable']) or 'none'}; "
        + (
            f"told weakly, shrunk towards their priors: {', '.join(model['shrunk_to_prior'])}"
            if model["shrunk_to_prior"]
            else f"fixed at their priors: {', '.join(model['fixed_at_prior']) or 'none'}"
        )
    )
    if model.get("probed_but_held_line"):
        click.echo(model["probed_but_held_line"])
    for group, out in fits.items():
        traits = ", ".join(
            f"{t} {v['mean']:.4g} (95 % {v['mean_ci95'][0]:.4g}-{v['mean_ci95'][1]:.4g}"
            f"{'' if v['identifiable'] else ', shrunk'})"
            for t, v in out["traits"].items()
            if v["fitted"]
        )
        click.echo(f"{group:<9} n = {out['participants']:>2}: {traits or 'no trait fitted'}")
    rows = table[table["source"] != "model"]  # type: ignore[index]
    click.echo(
        "group     measure                 cond   observed (95 % CI)       simulated (95 % CI)"
    )
    for (group, measure, condition), g in rows.groupby(
        ["group", "measure", "condition"], sort=False
    ):
        cells = []
        for source in ("observed", "simulated"):
            r = g[g["source"] == source].iloc[0]
            cells.append(f"{r['mean']:8.3f} ({r['ci_low']:.3f}, {r['ci_high']:.3f})")
        click.echo(f"{group:<9} {measure:<23} {condition:<6} {cells[0]:<24} {cells[1]}")
