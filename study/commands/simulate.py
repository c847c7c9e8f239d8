"""`study simulate`: one headless simulated trial, its samples, summary and figure."""

from __future__ import annotations

import json
from pathlib import Path

import click
from rich.console import Console

from study.commands.base import SEED, StudyCommand, load_participants, participants_option
from study.errors import StudyInputError
from study.protocol.design import DEFAULT_GROUPS, KNOWN_CONDITIONS
from study.protocol.tasks import get_task, task_names

MAX_TRIAL_S = 3600.0
"""The longest simulated trial, s (an hour: far beyond any trial of the paper)."""


@click.command("simulate", cls=StudyCommand)
@click.option(
    "--task",
    type=click.Choice(task_names()),
    default="lcca",
    show_default=True,
    help="The task of the trial.",
)
@click.option(
    "--group",
    type=click.Choice(DEFAULT_GROUPS),
    required=True,
    help="The simulated participant's group (its trait profile).",
)
@click.option(
    "--condition",
    type=click.Choice(KNOWN_CONDITIONS),
    required=True,
    help="VO (visual only: no haptic torque) or HV (haptic and visual).",
)
@click.option(
    "--haptic-gain",
    type=float,
    default=None,
    help="G_h in N m per N (eq. 7) [default: the paper's 0.02]; 0 with HV renders nothing. "
    "Only for tasks with a haptic dial (lcca).",
)
@click.option(
    "--seed", type=SEED, default=0, show_default=True, help="Seeds the participant and the run."
)
@click.option(
    "--out",
    "out_csv",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="The trial's samples CSV (its summary goes beside it, as .json).",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also draw the force traces to this file (.pdf, .svg or .png) [default: none].",
)
@click.option(
    "--estimator",
    "model_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Force estimator folder [default: the model shipped with haptic-study].",
)
@click.option(
    "--max-seconds",
    type=click.FloatRange(min=1, max=MAX_TRIAL_S),
    default=180.0,
    show_default=True,
    help="Stop the trial, unfinished, after this many simulated seconds.",
)
@participants_option
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
    participants_path: Path | None,
) -> None:
    """Run one simulated trial headless and write TRIAL.csv, TRIAL.json and a figure.

    \b
    Example:
      study simulate --group novice --condition HV --out trial.csv --plot trial.png
    """
    from study.protocol.default_estimator import load_estimator
    from study.protocol.traits import simulated_participant
    from study.protocol.trial_run import simulate_trial
    from teleop_core.follower.recording import write_csv_atomically

    for path in (out_csv, plot_path):
        if path is not None and not path.parent.is_dir():
            raise StudyInputError(f"folder {path.parent} for {path.name} does not exist")
    the_task = get_task(task)
    model = load_participants(participants_path)
    # refuse a bad gain, or a gain for a task without a dial, before any work
    the_task.haptic_gain(haptic_gain)
    if condition == "VO" and haptic_gain:
        raise StudyInputError(
            f"--haptic-gain {haptic_gain:g} with VO; VO renders no haptic torque "
            "(expected the gain with HV only)"
        )
    from study.protocol.parallel import compile_loop_once

    compile_loop_once(lambda message: click.echo(f"study simulate: {message}", err=True))
    estimator = load_estimator(model_dir) if the_task.has_dial else None
    traits = simulated_participant(group, seed, model)
    if model is not None:
        # one trial is the first of a session: the model's effects at its start
        from study.protocol.participant_effects import apply_effects, session_place

        first = session_place([condition], 0, 0, 1)
        traits = apply_effects(traits, model.participant_effects, first)
    with Console(stderr=True).status(f"simulating a {group} participant, {task}, {condition}"):
        result = simulate_trial(
            the_task,
            traits,
            condition,
            seed,
            max_seconds,
            haptic_gain_n_m_per_n=haptic_gain,
            estimator=estimator,
        )
    write_csv_atomically(result.frame, out_csv)
    summary_path = out_csv.with_suffix(".json")
    if estimator is not None:
        result.summary["estimator"] = "physics + GRU + EKF"
    if model is not None:
        result.summary["participant_model"] = {
            "path": str(participants_path),
            "digest": model.digest,
            "fitted_to": model.data_source,
        }
    summary_path.write_text(json.dumps(result.summary, indent=2) + "\n")
    if plot_path is not None:
        from study.analysis.trial_plot import trial_plot

        title = f"{task}, {group}, {condition}, seed {seed}"
        trial_plot(the_task, result.frame, title).savefig(plot_path, dpi=200)
    s = result.summary
    click.echo(
        f"{task} {group} {condition} seed {seed}: "
        f"{'success' if s['success'] else 'no success'} in {s['completion_time_s']:.1f} s, "
        + the_task.summary_line(s)
    )
    if model is not None:
        click.echo(f"simulated participant drawn from the {model.label()}")
    click.echo(f"samples: {out_csv}; summary: {summary_path}")
