"""`study estimator ...`: train the follower force estimator on a bench recording, and run it."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from study.commands.base import StudyGroup
from study.errors import StudyInputError

_err = Console(stderr=True)


@click.group("estimator", cls=StudyGroup)
def estimator() -> None:
    """Follower force estimator: physics model + GRU residual + EKF (seed 000)."""


@estimator.command("train")
@click.argument("recording", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Model folder to write (weights, standardisation, physics, EKF, summary.json).",
)
@click.option(
    "--window",
    type=click.IntRange(min=1),
    default=20,
    show_default=True,
    help="GRU input window T, samples.",
)
@click.option(
    "--epochs",
    type=click.IntRange(min=1),
    default=100,
    show_default=True,
    help="Most training epochs (the best validation epoch is kept).",
)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--hidden-size", type=click.IntRange(min=1), default=32, show_default=True)
@click.option(
    "--learning-rate", type=click.FloatRange(min=0, min_open=True), default=1e-4, show_default=True
)
@click.option(
    "--patience",
    type=click.IntRange(min=1),
    default=None,
    help="Stop after this many epochs without a better validation RMSE.",
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
@click.option("--force", is_flag=True, help="Replace an existing model folder.")
def train_cmd(
    recording: Path,
    out_dir: Path,
    window: int,
    epochs: int,
    seed: int,
    hidden_size: int,
    learning_rate: float,
    patience: int | None,
    ekf_q: float | None,
    calibration: Path | None,
    force: bool,
) -> None:
    """Fit eq. 1 to RECORDING, train the GRU on its residual, set up the EKF.

    RECORDING is a follower CSV (t, iq, theta, omega, f_ref; alpha optional).
    """
    from teleop_core.estimation.estimator import train_estimator
    from teleop_core.estimation.extended import ExtendedPhysics
    from teleop_core.estimation.gru import GruConfig
    from teleop_core.estimation.recording import FollowerRecording

    if out_dir.exists() and any(out_dir.iterdir()) and not force:
        raise StudyInputError(
            f"model folder {out_dir} exists and is not empty; expected a new folder (or --force)"
        )
    data = FollowerRecording.from_csv(recording)
    extension = ExtendedPhysics.read(calibration) if calibration is not None else None
    config = GruConfig(
        window=window,
        hidden_size=hidden_size,
        learning_rate=learning_rate,
        max_epochs=epochs,
        patience=patience,
    )
    with Progress(
        TextColumn("training GRU"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rmse]}"),
        TimeRemainingColumn(),
        console=_err,
        transient=True,
    ) as progress:
        task = progress.add_task("epochs", total=epochs, rmse="")

        def report(epoch: int, train_rmse: float, val_rmse: float) -> None:
            progress.update(
                task,
                completed=epoch,
                rmse=f"train {train_rmse:.4f} N, validation {val_rmse:.4f} N",
            )

        model, summary = train_estimator(
            data, config, seed=seed, ekf_q_n2=ekf_q, progress=report, extension=extension
        )
    model.save(out_dir, summary.to_dict())
    v = summary.validation_rmse_n
    click.echo(
        f"{out_dir}: best epoch {summary.best_epoch} of {summary.epochs_run}; validation RMSE "
        f"physics {v['physics']:.4f} N, physics+GRU {v['hybrid']:.4f} N, "
        f"after EKF {v['final']:.4f} N"
    )
    for note in summary.notes:
        click.echo(f"note: {note}")


@estimator.command("run")
@click.argument("model_dir", type=click.Path(file_okay=False, path_type=Path))
@click.argument("recording", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--out",
    "out_csv",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Predictions CSV: t, f_ref, f_physics, f_hybrid, f_final.",
)
def run_cmd(model_dir: Path, recording: Path, out_csv: Path) -> None:
    """Estimate the proximal force over RECORDING with the model in MODEL_DIR."""
    from teleop_core.estimation.estimator import ForceEstimator
    from teleop_core.estimation.metrics import rmse
    from teleop_core.estimation.recording import FollowerRecording, write_csv_atomically

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
    click.echo(
        f"{out_csv}: {len(result.t)} estimates; RMSE against f_ref: physics "
        f"{rmse(result.f_physics, result.f_ref):.4f} N, physics+GRU "
        f"{rmse(result.f_hybrid, result.f_ref):.4f} N, "
        f"after EKF {rmse(result.f_final, result.f_ref):.4f} N"
    )
