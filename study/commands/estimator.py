"""`study estimator ...`: train the follower force estimator on a bench recording, and run it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeRemainingColumn

from study.commands.base import (
    SEED,
    StudyGroup,
    count_option,
    file_option,
    out_dir_option,
    progress_bar,
)
from study.errors import StudyInputError
from teleop_core.errors import TeleopInputError

if TYPE_CHECKING:
    from teleop_core.estimation.estimator import EstimateResult, ForceEstimator
    from teleop_core.follower.recording import FollowerRecording

_err = Console(stderr=True)


@click.group("estimator", cls=StudyGroup)
def estimator() -> None:
    """Follower force estimator: physics model + GRU residual + EKF, after the endovascular paper.

    \b
    Example:
      study estimator train bench.csv --out model/
    """


@estimator.command("train")
@click.argument("recording", type=click.Path(dir_okay=False, path_type=Path))
@out_dir_option("Model folder to write (weights, standardisation, physics, EKF, summary.json).")
@count_option("--window", 20, "GRU input window T, samples.")
@count_option("--epochs", 100, "Most training epochs (the best validation epoch is kept).")
@click.option(
    "--seed", type=SEED, default=0, show_default=True, help="Seed of the split and the training."
)
@click.option(
    "--hidden-size",
    type=click.IntRange(min=1),
    default=32,
    show_default=True,
    help="Units of the GRU's hidden state.",
)
@click.option(
    "--learning-rate",
    type=click.FloatRange(min=0, min_open=True),
    default=1e-4,
    show_default=True,
    help="Adam's learning rate.",
)
@count_option("--patience", 10, "Stop after this many epochs without a better validation RMSE.")
@click.option(
    "--weight-decay",
    type=click.FloatRange(min=0),
    default=None,
    help="AdamW decoupled weight decay [default: GruConfig's].",
)
@click.option(
    "--dropout",
    type=click.FloatRange(min=0, max=1, max_open=True),
    default=None,
    help="Dropout on the GRU's last hidden state while training [default: GruConfig's].",
)
@click.option(
    "--input-noise",
    type=click.FloatRange(min=0),
    default=None,
    help="SD of noise added to the standardised training inputs [default: GruConfig's].",
)
@click.option(
    "--memory",
    default="ema",
    show_default=True,
    help="Memory features beside the window: 'ema' (I_q and theta_d minus their moving "
    "averages at 0.1, 0.3, 1 and 3 s), time constants in s such as 0.3,3, or 'none' (the "
    "plain window). Kept in the model folder.",
)
@click.option(
    "--ekf-q",
    "ekf_q",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="EKF process noise per step, N^2 [default: tuned on the training blocks].",
)
@click.option(
    "--calibration",
    "calibration",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="A `study calibrate --model follower` report: its calibrated model (eq. 1 plus "
    "the effects found) replaces eq. 1 as the physics stage, and the GRU learns what it "
    "still misses.",
)
@click.option(
    "--effects",
    type=click.Choice(["auto", "none"]),
    default="auto",
    show_default=True,
    help="auto: first look for the physical effects eq. 1 lacks (the calibration loop of "
    "`study calibrate`, on this recording); those it adds precede the GRU, which learns the "
    "rest. A model with effects runs over recordings (`study estimator run`), not in the "
    "loop: none gives eq. 1 + GRU, which the loop can run.",
)
@click.option(
    "--residual",
    "residual_stage",
    type=click.Choice(["gru", "trees", "auto"]),
    default="gru",
    show_default=True,
    help="The residual stage after the physics model: gru (the paper's), trees (gradient-"
    "boosted trees on the same windows; runs over recordings, not in the loop), or auto "
    "(both on the same training blocks; the one with the lower validation RMSE is kept).",
)
@click.option(
    "--validate",
    "validate",
    multiple=True,
    type=click.Path(dir_okay=False, path_type=Path),
    metavar="FILE",
    help="Another follower recording (repeatable): the trained estimator runs over it "
    "in full; summary.json's `validation` and a line each say how it does.",
)
@click.option("--force", is_flag=True, help="Replace an existing model folder.")
def train_cmd(
    recording: Path,
    out_dir: Path,
    window: int,
    epochs: int,
    seed: int,
    hidden_size: int,
    learning_rate: float,
    patience: int,
    weight_decay: float | None,
    dropout: float | None,
    input_noise: float | None,
    memory: str,
    ekf_q: float | None,
    calibration: Path | None,
    effects: str,
    residual_stage: str,
    validate: tuple[Path, ...],
    force: bool,
) -> None:
    """Fit eq. 1 to RECORDING, train the GRU (or trees) on its residual, set up the EKF.

    RECORDING is a follower CSV (t, iq, theta, omega, f_ref; alpha optional).

    \b
    Example:
      study estimator train bench.csv --out model/
    """
    # lazy: teleop_core.estimation.extended (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.estimation.extended import ExtendedPhysics

    # lazy: teleop_core.estimation.gru (with numpy) costs 75 ms at start-up
    from teleop_core.estimation.gru import GruConfig

    # lazy: teleop_core.estimation.memory (with numpy) costs 66 ms at start-up
    from teleop_core.estimation.memory import MemorySpec

    # lazy: teleop_core.estimation.training (with scipy, pandas, pyarrow) costs 0.6 s at start-up
    from teleop_core.estimation.training import train_estimator

    # lazy: teleop_core.follower.recording (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.follower.recording import FollowerRecording

    # lazy: teleop_core.recording_checks (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.recording_checks import check_varies

    if out_dir.exists() and any(out_dir.iterdir()) and not force:
        raise StudyInputError(
            f"model folder {out_dir} exists and is not empty; expected a new folder (or --force)"
        )
    data = FollowerRecording.from_csv(recording)
    check_varies(
        {"iq": data.iq, "omega": data.omega, "f_ref": data.f_ref},
        ("iq", "omega", "f_ref"),
        f"recording {recording}",
        TeleopInputError,
    )
    validation = [(path, FollowerRecording.from_csv(path, min_rows=window)) for path in validate]
    extension = ExtendedPhysics.read(calibration) if calibration is not None else None
    defaults = GruConfig()
    config = GruConfig(
        window=window,
        hidden_size=hidden_size,
        learning_rate=learning_rate,
        max_epochs=epochs,
        patience=patience,
        memory=MemorySpec.parse(memory),
        weight_decay=defaults.weight_decay if weight_decay is None else weight_decay,
        dropout=defaults.dropout if dropout is None else dropout,
        input_noise=defaults.input_noise if input_noise is None else input_noise,
    )
    with progress_bar(
        TextColumn("training GRU"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rmse]}"),
        TimeRemainingColumn(),
        console=_err,
    ) as progress:
        task = progress.add_task("epochs", total=epochs, rmse="")

        def report(step: str, done: int = 0, total: int = 0) -> None:
            progress.update(task, completed=done, rmse=step)

        model, summary = train_estimator(
            data,
            config,
            seed=seed,
            ekf_q_n2=ekf_q,
            progress=report,
            extension=extension,
            effects=effects == "auto",
            residual_stage=residual_stage,
        )
    validated = [_validation(model, path, rec) for path, rec in validation]
    model.save(out_dir, {**summary.to_dict(), "validation": [v[0] for v in validated]})
    v = summary.validation_rmse_n
    with_effects = f"eq. 1 + effects {v['effects']:.4f} N, " if "effects" in v else ""
    chosen = summary.residual["chosen"]
    stage = "physics+GRU" if chosen == "gru" else "physics+trees"
    trained = (
        f"best epoch {summary.best_epoch} of {summary.epochs_run}"
        if chosen == "gru"
        else "residual stage: trees"
    )
    click.echo(
        f"{out_dir}: {trained}; validation RMSE "
        f"physics {v['physics']:.4f} N, {with_effects}{stage} {v['hybrid']:.4f} N, "
        f"after EKF {v['final']:.4f} N"
    )
    if residual_stage == "auto":
        stages = summary.residual["validation_rmse_n"]
        click.echo(
            f"residual stage: {chosen}, the lower validation RMSE of physics+residual "
            f"(GRU {stages['gru']:.4f} N, trees {stages['trees']:.4f} N)"
        )
    _echo_regimes("validation RMSE per regime", summary.validation_rmse_by_regime_n)
    for entry, hybrid in validated:
        click.echo(
            f"validation {entry['recording']}: RMSE physics {entry['rmse_base']:.4f} N, "
            f"{stage} {hybrid:.4f} N, after EKF {entry['rmse_final']:.4f} N, fit "
            f"{entry['fit_percent']:.1f} % over {entry['samples']} estimates"
        )
    for note in summary.notes:
        click.echo(f"note: {note}")


def _validation(
    model: ForceEstimator, path: Path, recording: FollowerRecording
) -> tuple[dict[str, Any], float]:
    """The trained estimator over all of another recording (resampled to the model's
    rate where it differs): summary.json's entry (`recording`, `rmse_base`: the physics
    stage, `rmse_final`: after the EKF, `fit_percent` of the final estimate,
    `samples`: the estimates, one per sample with a full window) and physics +
    residual stage's RMSE."""
    # lazy: teleop_core.calibration.verdict costs 1.3 s at start-up
    from teleop_core.calibration.verdict import fit_percent

    # lazy: teleop_core.estimation.metrics (with numpy) costs 64 ms at start-up
    from teleop_core.estimation.metrics import rmse

    result = model.predict(model.conform(recording))
    entry = {
        "recording": str(path),
        "rmse_base": rmse(result.f_physics, result.f_ref),
        "rmse_final": rmse(result.f_final, result.f_ref),
        "fit_percent": fit_percent(result.f_ref, result.f_final),
        "samples": len(result.t),
    }
    return entry, rmse(result.f_hybrid, result.f_ref)


def _echo_regimes(title: str, table: dict[str, dict[str, float]]) -> None:
    """One line per regime label: samples and the RMSE of each stage (N)."""
    click.echo(f"{title} (physics / physics+GRU / after EKF, N):")
    for label, row in table.items():
        click.echo(
            f"  {label:<20} {int(row['samples']):>7} samples  {row['physics']:.4f} / "
            f"{row['hybrid']:.4f} / {row['final']:.4f}"
        )


@estimator.command("run")
@click.argument("model_dir", type=click.Path(file_okay=False, path_type=Path))
@click.argument("recording", type=click.Path(dir_okay=False, path_type=Path))
@file_option(
    "--out",
    "out_csv",
    "Predictions CSV: t, f_ref, f_physics, f_hybrid, f_final, in_range (and f_effects, eq. 1 "
    "with the effects training found, for a model with effects).",
)
def run_cmd(model_dir: Path, recording: Path, out_csv: Path) -> None:
    """Estimate the proximal force over RECORDING with the model in MODEL_DIR.

    `in_range` is 1 where the sample's inputs (iq, omega, alpha) lie inside the range
    the model was trained on, 0 where one leaves it (empty for a model saved before the
    range was kept).

    \b
    Example:
      study estimator run model/ bench.csv --out forces.csv
    """
    # lazy: teleop_core.estimation.estimator (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.estimation.estimator import ForceEstimator

    # lazy: teleop_core.estimation.metrics (with numpy) costs 64 ms at start-up
    from teleop_core.estimation.metrics import rmse

    # lazy: teleop_core.follower.recording (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.follower.recording import FollowerRecording, write_csv_atomically

    model = ForceEstimator.load(model_dir)
    data = FollowerRecording.from_csv(recording, min_rows=model.window)
    with _err.status("estimating"):
        conformed = model.conform(data)
        result = model.predict(conformed)
        write_csv_atomically(result.to_frame(), out_csv)
    if conformed is not data:
        click.echo(
            f"note: {recording.name} was sampled at {data.sample_rate_hz:.6g} Hz; resampled to the "
            f"model's {model.sample_rate_hz:.6g} Hz"
        )
    with_effects = (
        ""
        if result.f_effects is None
        else f"eq. 1 + effects {rmse(result.f_effects, result.f_ref):.4f} N, "
    )
    stage = "physics+GRU" if model.residual == "gru" else "physics+trees"
    click.echo(
        f"{out_csv}: {len(result.t)} estimates; RMSE against f_ref: physics "
        f"{rmse(result.f_physics, result.f_ref):.4f} N, {with_effects}{stage} "
        f"{rmse(result.f_hybrid, result.f_ref):.4f} N, "
        f"after EKF {rmse(result.f_final, result.f_ref):.4f} N"
    )
    if result.in_range is None or model.input_range is None:
        click.echo("note: the model keeps no training range (saved before it was kept)")
    else:
        from teleop_core.estimation.estimator import features_of

        window = model.window
        outside = model.input_range.outside_by_feature(features_of(conformed)[window - 1 :])
        click.echo(
            f"outside the training range: {100 * (1 - result.in_range.mean()):.1f} % of the "
            "estimates (" + ", ".join(f"{k} {100 * v:.1f} %" for k, v in outside.items()) + ")"
        )
    regimes = _regimes_of(model_dir, conformed, result)
    if regimes:
        _echo_regimes("RMSE per regime", regimes)


def _regimes_of(
    model_dir: Path, recording: FollowerRecording, result: EstimateResult
) -> dict[str, dict[str, float]]:
    """RMSE per regime label, with the thresholds the model was trained with (if kept)."""

    # lazy: teleop_core.estimation.regimes (with scipy, numpy) costs 0.3 s at start-up
    from teleop_core.estimation.regimes import RegimeRules, label_samples, regime_rmse

    rules = json.loads((model_dir / "summary.json").read_text()).get("regime_rules")
    if not rules:
        return {}
    T = len(recording) - len(result.t) + 1
    masks = label_samples(
        recording.omega, recording.f_ref, recording.sample_rate_hz, RegimeRules(**rules)
    )
    return regime_rmse(
        {k: m[T - 1 :] for k, m in masks.items()},
        result.f_ref,
        physics=result.f_physics,
        hybrid=result.f_hybrid,
        final=result.f_final,
    )
