"""`study simulate`: one headless simulated trial, its samples, summary and figure."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.console import Console

from study.commands.base import StudyCommand

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from study.protocol.lcca_trial import TrialResult
from study.errors import StudyInputError
from study.protocol.design import DEFAULT_GROUPS, KNOWN_CONDITIONS


@click.command("simulate", cls=StudyCommand)
@click.option("--task", type=click.Choice(["lcca", "notes"]), default="lcca", show_default=True)
@click.option("--group", type=click.Choice(DEFAULT_GROUPS), required=True)
@click.option("--condition", type=click.Choice(KNOWN_CONDITIONS), required=True)
@click.option(
    "--haptic-gain",
    type=float,
    default=None,
    help="G_h in N m per N (eq. 7) [default: the device's 0.02]; 0 with HV renders nothing.",
)
@click.option(
    "--seed", type=int, default=0, show_default=True, help="Seeds the participant and the run."
)
@click.option("--out", "out_csv", required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--estimator",
    "model_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Force estimator folder [default: the model shipped with haptic-study].",
)
@click.option("--max-seconds", type=click.FloatRange(min=1), default=180.0, show_default=True)
def simulate(
    task: str,
    group: str,
    condition: str,
    haptic_gain: float | None,
    seed: int,
    out_csv: Path,
    plot_path: Path | None,
    model_dir: Path | None,
    max_seconds: float,
) -> None:
    """Run one simulated trial headless and write TRIAL.csv, TRIAL.json and a figure."""
    from study.protocol.default_estimator import load_estimator
    from study.protocol.lcca_trial import condition_haptics, run_lcca_trial, simulated_participant
    from teleop_core.estimation.recording import write_csv_atomically

    for path in (out_csv, plot_path):
        if path is not None and not path.parent.is_dir():
            raise StudyInputError(f"folder {path.parent} for {path.name} does not exist")
    condition_haptics(condition, haptic_gain)  # refuse a bad gain before any work
    from teleop_core.loop import kernel

    kernel.COMPILE_NOTICE = lambda message: click.echo(f"study simulate: {message}", err=True)
    if task == "notes":
        result, plot, line = _simulate_notes(group, condition, seed, max_seconds)
    else:
        estimator = load_estimator(model_dir)
        traits = simulated_participant(group, seed)
        with Console(stderr=True).status(f"simulating a {group} participant, {condition}"):
            result = run_lcca_trial(traits, condition, seed, estimator, haptic_gain, max_seconds)
        s = result.summary
        line = (
            f"peak proximal {s['peak_proximal_force_n']:.3f} N, "
            f"peak distal {s['peak_distal_force_n']:.3f} N, {s['wall_contacts']} wall contacts"
        )

        def plot(frame: pd.DataFrame, title: str) -> Figure:
            from study.analysis.phantom_figures import plot_trial
            from teleop_core.phantom.lcca import LccaPhantom

            return plot_trial(frame, LccaPhantom(), title)

    write_csv_atomically(result.frame, out_csv)
    summary_path = out_csv.with_suffix(".json")
    summary_path.write_text(json.dumps(result.summary, indent=2) + "\n")
    if plot_path is not None:
        plot(result.frame, f"{task}, {group}, {condition}, seed {seed}").savefig(plot_path, dpi=200)
    s = result.summary
    click.echo(
        f"{task} {group} {condition} seed {seed}: "
        f"{'success' if s['success'] else 'no success'} in {s['completion_time_s']:.1f} s, " + line
    )
    click.echo(f"samples: {out_csv}; summary: {summary_path}")


def _simulate_notes(
    group: str, condition: str, seed: int, max_seconds: float
) -> tuple[TrialResult, Callable[[pd.DataFrame, str], Figure], str]:
    """`--task notes`: one NOTES trial (seed 001) with the group's simulated participant;
    (result, its plot function, the summary line's measures)."""
    from study.analysis.notes_figures import notes_trial_plot
    from study.protocol.lcca_trial import simulated_participant
    from study.protocol.notes_trial import run_notes_trial

    traits = simulated_participant(group, seed)
    with Console(stderr=True).status(f"simulating a {group} participant, NOTES, {condition}"):
        result = run_notes_trial(traits, condition, seed, max_seconds)
    s = result.summary
    line = (
        f"peak force demanded {s['peak_force_demanded_n']:.2f} N / rendered "
        f"{s['peak_force_rendered_n']:.2f} N, peak torque demanded "
        f"{s['peak_torque_demanded_n_m'] * 1e3:.1f} N mm / rendered "
        f"{s['peak_torque_rendered_n_m'] * 1e3:.1f} N mm, push over capacity "
        f"{s['push_over_capacity_fraction']:.1%} of the time"
    )
    return result, notes_trial_plot, line
