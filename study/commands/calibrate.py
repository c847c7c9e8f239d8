"""`study calibrate`: what the physics model still lacks, found on a bench recording.

Runs the calibration loop of `teleop_core.calibration` (base model, held-out residual,
candidate effects added while they help significantly) and writes the report, the
held-out predictions and the residual figures. Everything is computed before anything
is written, and each file is written through a temporary name, so a refused or failed
run leaves no half-written output.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn

from study.commands.base import (
    StudyCommand,
    check_parent_folder,
    file_option,
    json_option,
    out_dir_option,
    progress_bar,
    write_json_atomically,
)
from study.errors import StudyInputError

_err = Console(stderr=True)
MODELS = ("follower", "master", "notes-translation", "notes-rotation", "rigid-axis")
DRIVE_LABELS = {
    "follower": "q-axis current (A)",
    "master": "current (mA)",
    "notes-translation": "commanded force (N)",
    "notes-rotation": "commanded torque (N m)",
    "rigid-axis": "force u (N or N m)",
}


def _mat_columns(text: str) -> tuple[str, str, str]:
    """`t=t,q=qm,u=gtau*vir` -> ("t", "qm", "gtau*vir")."""
    pairs = dict(p.split("=", 1) for p in text.split(",") if "=" in p)
    if set(pairs) != {"t", "q", "u"} or len(text.split(",")) != 3:
        raise StudyInputError(
            f"--mat-columns {text!r}; expected t=NAME,q=NAME,u=NAME (products allowed: u=gtau*vir)"
        )
    return pairs["t"].strip(), pairs["q"].strip(), pairs["u"].strip()


def _base_model(
    recording: Path, model_name: str, held_out: float, mat_columns: str | None, units: str | None
) -> Any:
    """The base model of `model_name`; the rigid axis's with its derivative cutoff fitted
    on the training share and its axis from `units`, else from the recording's unit
    suffixes, else linear."""
    # lazy: teleop_core.calibration (with scipy, statsmodels, pandas) costs 1.3 s at start-up
    from teleop_core.calibration import BASE_MODELS

    # lazy: teleop_core.calibration.rigid_axis costs 1.3 s at start-up
    from teleop_core.calibration.rigid_axis import RigidAxisBase, recording_axis

    if recording.suffix.lower() == ".mat" and (model_name != "rigid-axis" or not mat_columns):
        raise StudyInputError(
            f"{recording} is a MATLAB file; expected --model rigid-axis with --mat-columns "
            "t=NAME,q=NAME,u=NAME naming its variables (products allowed: u=gain*volt)"
        )
    if model_name != "rigid-axis":
        if units is not None:
            raise StudyInputError(
                f"--units {units} with --model {model_name}; expected --units only with "
                "--model rigid-axis (the other models' contracts fix their units)"
            )
        return BASE_MODELS[model_name]
    columns = _mat_columns(mat_columns) if mat_columns else None
    said = recording_axis(recording, columns) if columns else recording_axis(recording)
    axis = units or said or "linear"
    return RigidAxisBase(train_fraction=1.0 - held_out, mat_columns=columns, axis=axis)


def run_calibration(
    recording: Path,
    model_name: str,
    held_out: float,
    max_effects: int,
    families: str | None,
    mat_columns: str | None = None,
    units: str | None = None,
    validate: Sequence[Path] = (),
) -> Any:
    """Read RECORDING for `model_name` (and each recording of `validate`, as RECORDING
    was read: all are refused before the loop runs) and run the loop with a progress
    display; the fitted model then predicts each of `validate` in full."""
    # lazy: teleop_core.calibration (with scipy, statsmodels, pandas) costs 1.3 s at start-up
    from teleop_core.calibration import Calibrator

    model = _base_model(recording, model_name, held_out, mat_columns, units)
    data = model.read(recording)
    reader = model.reader_for(data.preparation)
    validation = [(str(path), reader.read(path)) for path in validate]
    chosen = [f.strip() for f in families.split(",")] if families else None
    calibrator = Calibrator(
        model, families=chosen, held_out_fraction=held_out, max_effects=max_effects
    )
    with progress_bar(
        TextColumn("calibrating {task.fields[what]}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=_err,
    ) as progress:
        task = progress.add_task("calibration", total=None, what="", unit="families")

        def report(step: str, done: int = 0, total: int = 0) -> None:
            progress.update(task, completed=done, total=total or None, what=step)

        calibrator.fit(data, progress=report, validation=validation)
    return calibrator


@click.command("calibrate", cls=StudyCommand)
@click.argument("recording", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--model",
    "model_name",
    type=click.Choice(MODELS),
    default="follower",
    show_default=True,
    help="Base model and recording contract.",
)
@json_option(
    "Report: RMSE before/after, effects added, candidates rejected, residual tests "
    "[default: report.json in the --out folder].",
    required=False,
)
@file_option(
    "--predictions",
    "pred_path",
    "Held-out predictions CSV: t, f_ref, f_base, f_final [default: predictions.csv in "
    "the --out folder].",
    required=False,
)
@out_dir_option(
    "Folder for the residual figures, and the report and predictions unless named "
    "(created if its parent exists) [default: RECORDING's name with -calibration, in the "
    "current folder].",
    required=False,
)
@click.option(
    "--held-out",
    type=click.FloatRange(0.05, 0.5),
    default=0.25,
    show_default=True,
    help="Share of the recording held out for testing: at its end, or for a NOTES chirp at "
    "the end of each of 8 segments of the sweep.",
)
@click.option(
    "--max-effects",
    type=click.IntRange(min=0),
    default=4,
    show_default=True,
    help="Most effects the loop adds to the base model (0: fit and report the base model).",
)
@click.option(
    "--mat-columns",
    default=None,
    metavar="t=NAME,q=NAME,u=NAME",
    help="For a MATLAB .mat RECORDING (--model rigid-axis, required then): the variables, "
    "or products of them, that give t, q and u (e.g. t=time,q=pos,u=gain*volt); every "
    "other vector of the same length is an extra channel.",
)
@click.option(
    "--families",
    default=None,
    metavar="LIST",
    help="Comma-separated candidate families [default: all that apply to the model].",
)
@click.option(
    "--validate",
    "validate",
    multiple=True,
    type=click.Path(dir_okay=False, path_type=Path),
    metavar="FILE",
    help="Another recording of the same machine (repeatable): the calibrated model, "
    "fitted on RECORDING, predicts it in full; the report's `validation` and "
    "validation.png say how it does.",
)
@click.option(
    "--units",
    type=click.Choice(["linear", "rotary"]),
    default=None,
    help="For --model rigid-axis: a linear axis (q in m, u in N) or a rotary one (q in "
    "rad, u in N m) [default: from the unit suffixes of the columns (q_m, u_n; q_rad, "
    "u_n_m), else linear].",
)
def calibrate(
    recording: Path,
    model_name: str,
    json_path: Path | None,
    pred_path: Path | None,
    out_dir: Path | None,
    held_out: float,
    max_effects: int,
    mat_columns: str | None,
    families: str | None,
    validate: tuple[Path, ...],
    units: str | None,
) -> None:
    """Fit the base model to RECORDING, find and add the effects it lacks, report.

    RECORDING is a follower CSV (t, iq, theta, omega, f_ref; alpha optional) for
    --model follower, the dial's calibration (t, current_ma, f_ref) for --model
    master, or a clamped NOTES ramp or chirp run (t, f_des, f_ee) for --model
    notes-translation or notes-rotation, or any drive's recording (t, q, u: position
    in m or rad, force in N or N m; other numeric columns are extra channels) for
    --model rigid-axis, which also reads a MATLAB v5 .mat file (see --mat-columns).

    \b
    Example:
      study calibrate bench.csv --model follower     # writes bench-calibration/
    """
    # lazy: pandas costs 0.4 s at start-up
    import pandas as pd

    # lazy: study.analysis.calibration_figures costs 1.7 s at start-up
    from study.analysis.calibration_figures import (
        held_out_mask,
        overview_figures,
        residual_figures,
        signal_labels,
        validation_figure,
    )

    # lazy: teleop_core.calibration.verdict costs 1.3 s at start-up
    from teleop_core.calibration.verdict import quantities

    # lazy: teleop_core.follower.recording (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.follower.recording import write_csv_atomically

    out_dir, json_path, pred_path = output_paths(recording, out_dir, json_path, pred_path)
    calibrator = run_calibration(
        recording, model_name, held_out, max_effects, families, mat_columns, units, validate
    )
    report = calibrator.report()
    data, test = calibrator.data_, calibrator.test_
    before = data.y[test] - calibrator.base_prediction_[test]
    after = data.y[test] - calibrator.prediction_[test]
    predictions = pd.DataFrame(
        {
            "t": data.signals["t"][test],
            "f_ref": data.y[test],
            "f_base": calibrator.base_prediction_[test],
            "f_final": calibrator.prediction_[test],
        }
    )
    unit = calibrator.model.output_unit
    position_unit = calibrator.model.units().get("position")
    held = held_out_mask(len(data), test)
    named = report["unexplained"]["quantity"] if report["unexplained"] else None
    # the quantity as the verdict binned it (smoothed channels), over the held-out rows
    x_named = (
        quantities({k: v[test] for k, v in data.signals.items()}, calibrator.prediction_[test]).get(
            named
        )
        if named
        else None
    )
    out_dir.mkdir(exist_ok=True)
    overview_figures(
        out_dir,
        data.signals["t"],
        data.y - calibrator.base_prediction_,
        data.y - calibrator.prediction_,
        held,
        report,
        x_named,
        model_name,
        unit,
        position_unit,
    )
    residual_figures(
        out_dir,
        {k: v[test] for k, v in data.signals.items()},
        before,
        after,
        report["residual_tests_before"],
        report["residual_tests_after"],
        calibrator.model.plot_against,
        DRIVE_LABELS.get(model_name, "current"),
        unit,
        signal_labels(model_name, position_unit),
    )
    validation_figure(out_dir, calibrator.validation_, unit)
    write_csv_atomically(predictions, pred_path)
    write_json_atomically(report, json_path)
    added = ", ".join(e["family"] for e in report["effects_added"]) or "none"
    click.echo(
        f"{recording.name}: held-out RMSE {report['rmse_before']:.4f} {unit} -> "
        f"{report['rmse_after']:.4f} {unit} (fit {report['fit_percent_before']:.1f} % -> "
        f"{report['fit_percent_after']:.1f} %); effects added: {added}"
    )
    click.echo(_verdict_line(report))
    for v in report["validation"]:
        click.echo(
            f"validation {v['recording']}: RMSE {v['rmse_base']:.4f} {unit} (base model) -> "
            f"{v['rmse_final']:.4f} {unit} (calibrated), fit {v['fit_percent']:.1f} % over "
            f"all {v['samples']} samples"
        )
    # lazy: teleop_core.calibration.fitting costs 1.3 s at start-up
    from teleop_core.calibration.fitting import params_text

    for effect in report["effects_added"]:
        params = params_text(effect["params"], effect["ci"], 3)
        click.echo(f"  {effect['family']}: {params} -> {effect['rmse_after_step']:.4f} {unit}")
    for effect in report["ambiguous_effects"]:
        first, *others = effect["families"]
        click.echo(
            f"  ambiguous: {first} or {' or '.join(others)} (the held-out block does not tell "
            f"them apart; modelled as {first}) -> {effect['rmse_after_step']:.4f} {unit}"
        )
    for tell in report["to_tell_apart"]:
        what = " or ".join(tell["effects"]) or "what remains"
        click.echo(f"  to tell {what} apart: record {tell['channel']}; run {tell['excitation']}")
    for warning in report["warnings"]:
        click.echo(f"note: {warning}")


def output_paths(
    recording: Path, out_dir: Path | None, json_path: Path | None, pred_path: Path | None
) -> tuple[Path, Path, Path]:
    """The figures' folder, the report and the predictions: as given, or the defaults
    (`RECORDING-calibration/` in the current folder, holding `report.json` and
    `predictions.csv`); each given one's folder must exist."""
    for given in (json_path, pred_path, out_dir):
        if given is not None:
            check_parent_folder(given)
    folder = out_dir if out_dir is not None else Path(f"{recording.stem}-calibration")
    return (
        folder,
        json_path if json_path is not None else folder / "report.json",
        pred_path if pred_path is not None else folder / "predictions.csv",
    )


def _verdict_line(report: dict[str, Any]) -> str:
    """The verdict in one line: white, or where the structure that remains lies."""
    if report["verdict"] == "white":
        return "verdict: white (the held-out residual shows no structure left)"
    where = report["unexplained"]
    if where["share_beyond_chance"] >= 0.02:
        place = (
            f"{where['quantity']} explains {100 * where['share_of_variance']:.0f} % of "
            f"the held-out residual's variance"
        )
    else:
        place = "no recorded channel or derived quantity explains it beyond chance"
    remains = [t for t in report.get("to_tell_apart", []) if "along" in t]
    suspects = f"; suspects: {', '.join(remains[0]['effects'])}" if remains else ""
    return f"verdict: structure remains, unexplained; {place}{suspects}"
