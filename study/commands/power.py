"""`study power`: power of the VO-HV comparison at the design's group sizes, by simulation."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import click
from click.core import ParameterSource

from study.analysis.task_figures import trace_measure
from study.commands.base import (
    SEED,
    StudyCommand,
    bar_progress,
    file_option,
    load_participants,
    out_dir_option,
    participants_option,
    progress_bar,
)
from study.errors import StudyInputError
from study.protocol.design import parse_design
from study.protocol.tasks import get_task

if TYPE_CHECKING:
    from study.protocol.participant_model import ParticipantModel


MAX_EFFECT = 10.0
"""The largest standardised effect (in SDs of the difference) `--effect` takes: beyond it
every test rejects and the simulation says nothing."""
MAX_N_SIM = 100_000
"""The most simulated studies per design size (`--n-sim`): Monte-Carlo SE 0.0016 at most."""


def _effects(text: str, groups: list[str]) -> dict[str, float]:
    """'0.8' for every group, or 'outsider=0.5,novice=0.8,expert=0.8'."""
    try:
        if "=" not in text:
            effects = dict.fromkeys(groups, float(text))
        else:
            pairs = dict(item.split("=", 1) for item in text.split(","))
            effects = {g.strip(): float(v) for g, v in pairs.items()}
    except ValueError:
        raise StudyInputError(
            f"--effect {text!r}; expected a number or group=number pairs, e.g. novice=0.8"
        ) from None
    for group, value in effects.items():
        if not (math.isfinite(value) and abs(value) <= MAX_EFFECT):
            raise StudyInputError(
                f"--effect {text!r}: {group} {value!r}; expected a finite standardised effect "
                f"from -{MAX_EFFECT:g} to {MAX_EFFECT:g}"
            )
    missing = [g for g in groups if g not in effects]
    unknown = [g for g in effects if g not in groups]
    if missing or unknown:
        raise StudyInputError(
            f"--effect {text!r} names {', '.join(unknown) or 'no unknown group'} and lacks "
            f"{', '.join(missing) or 'none'}; expected every design group: {', '.join(groups)}"
        )
    return effects


def model_measure(model: ParticipantModel) -> str:
    """The measure whose effect `study power` takes from a model by default."""
    return trace_measure(get_task(model.task))


def _model_effects(
    ctx: click.Context, model: ParticipantModel, groups: list[str], measure: str | None
) -> tuple[dict[str, float], float]:
    """The fitted model's standardised effect per group and its mean VO-HV correlation."""

    for name, option in (("effect", "--effect"), ("rho", "--correlation")):
        if ctx.get_parameter_source(name) is not ParameterSource.DEFAULT:
            raise StudyInputError(
                f"{option} with --participants; expected one of them (the "
                "model gives the effects and the correlation)"
            )
    measure = measure or model_measure(model)
    missing = [g for g in groups if measure not in model.effects.get(g, {})]
    if missing:
        raise StudyInputError(
            f"participant model {model.source} has no effect of {measure!r} "
            f"for group {missing[0]}; expected a model fitted to every "
            "design group and a measure of its task"
        )
    effects = {g: float(model.effects[g][measure]["effect"]) for g in groups}
    rhos = [float(model.effects[g][measure]["correlation"]) for g in groups]
    return effects, min(max(sum(rhos) / len(rhos), 0.0), 0.99)


@click.command("power", cls=StudyCommand)
@file_option(
    "--design",
    "design_path",
    "The study design (TOML) whose groups, trials and tasks are simulated.",
)
@click.option(
    "--effect",
    default="0.8",
    show_default=True,
    help="HV-VO effect in per-condition SDs (the mean difference over the SD of one "
    "condition; Cohen's d_z = effect / sqrt(2 (1 - correlation)), equal only at 0.5): "
    "one number, or group=number for each group.",
)
@click.option(
    "--correlation",
    "rho",
    type=click.FloatRange(0, 1, max_open=True),
    default=0.5,
    show_default=True,
    help="Correlation of a participant's VO and HV outcomes.",
)
@click.option(
    "--n-sim",
    type=click.IntRange(min=10, max=MAX_N_SIM),
    default=500,
    show_default=True,
    help="Simulated studies per sample size.",
)
@click.option(
    "--seed", type=SEED, default=0, show_default=True, help="Seed of the simulated studies."
)
@out_dir_option("Write power.json and the power curve (PDF, PNG) here.", required=False)
@participants_option
@click.option(
    "--measure",
    default=None,
    help="With --participants: the measure whose fitted effect is used "
    "[default: the task's last analysed one]; without: the measure --effect is of, "
    "named in the output [default: none named].",
)
@click.pass_context
def power(
    ctx: click.Context,
    design_path: Path,
    effect: str,
    rho: float,
    n_sim: int,
    seed: int,
    out_dir: Path | None,
    participants_path: Path | None,
    measure: str | None,
) -> None:
    """Power of VO vs HV in each group and of the group x condition interaction.

    With --participants MODEL.json the effects and the correlation are those the fitted
    participant model simulates (its `effects`), instead of --effect and --correlation.

    \b
    Example:
      study power --design design.toml --n-sim 200
    """
    # lazy: study.analysis.power (with scipy, numpy) costs 0.8 s at start-up
    from study.analysis.power import SCALES, power_curve

    # lazy: study.protocol.csv_input (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.protocol.csv_input import read_text_file

    text = read_text_file(design_path, "design file", "a UTF-8 TOML file")
    design = parse_design(text, str(design_path))
    model = load_participants(participants_path)
    if model is None:
        effects = _effects(effect, list(design.groups))
    else:
        effects, rho = _model_effects(ctx, model, list(design.groups), measure)
    with progress_bar() as bar:
        task = bar.add_task("simulated studies", total=n_sim * len(SCALES))
        told = bar_progress(bar, task, describe=False)
        curve = power_curve(design.groups, effects, rho, n_sim, seed, told)
    # lazy: study.analysis.power (with scipy, numpy) costs 0.8 s at start-up
    from study.analysis.power import CORRECTION, dz_of

    at_design = next(r for s, r in curve if s == 1.0)
    named = measure or (model_measure(model) if model else None)
    click.echo(
        f"measure: {named or 'none named (a standardised effect)'}; effect in per-condition "
        f"SDs, d_z at correlation {rho:g} in brackets; power with {CORRECTION}"
    )
    for group, p in at_design.groups.items():
        click.echo(
            f"{group:<10} n = {at_design.sizes[group]:>3}  effect {effects[group]:g} "
            f"(d_z {dz_of(effects[group], rho):.3g})  power {p:.3f} "
            f"(uncorrected {at_design.groups_uncorrected[group]:.3f})"
        )
    if at_design.interaction is not None:
        what = "power" if at_design.interaction_is_power else "type I error rate (equal effects)"
        click.echo(f"group x condition interaction: {what} {at_design.interaction:.3f}")
    if out_dir is not None:
        from study.analysis.figures import save
        from study.analysis.paper import CAPTIONS
        from study.analysis.power_plot import plot_power_curve, power_caption

        out_dir.mkdir(parents=True, exist_ok=True)
        report = {
            "design": design.groups,
            "measure": named,
            "effects": effects,
            "effect_units": "per-condition SD (mean HV - VO over the SD of one condition)",
            "effects_dz": {g: dz_of(e, rho) for g, e in effects.items()},
            "correction": CORRECTION,
            "groups_uncorrected": at_design.groups_uncorrected,
            "correlation": rho,
            "n_sim": n_sim,
            **(
                {
                    "participant_model": {
                        "path": str(participants_path),
                        "digest": model.digest,
                        "fitted_to": model.data_source,
                        "measure": measure or model_measure(model),
                    }
                }
                if model
                else {}
            ),
            "seed": seed,
            "groups": at_design.groups,
            "interaction": at_design.interaction,
            "interaction_is_power": at_design.interaction_is_power,
            "curve": [
                {"scale": s, "sizes": r.sizes, "groups": r.groups, "interaction": r.interaction}
                for s, r in curve
            ],
        }
        (out_dir / "power.json").write_text(json.dumps(report, indent=2) + "\n")
        fig = plot_power_curve(curve, n_sim=n_sim)
        paths = save(fig, out_dir, "power_curve", ("pdf", "png"))
        captions = out_dir / CAPTIONS
        caption = power_caption(effects, rho, n_sim, named)
        names = ", ".join(path.name for path in paths)
        captions.write_text(f"# Figure captions\n\n## {names}\n\n{caption}\n", encoding="utf-8")
        for path in [*paths, captions]:
            click.echo(str(path))
