"""`study identify notes`: fit the NOTES model to one recorded bench file ([notes], III)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from study.commands.base import (
    StudyCommand,
    StudyGroup,
    check_parent_folder,
    json_option,
    out_dir_option,
)
from study.errors import StudyInputError


@click.group("identify", cls=StudyGroup)
def identify() -> None:
    """Identify a haptic device's model from recorded bench data.

    \b
    Example:
      study identify notes chirp.csv --dof translation --json fit.json
    """


@identify.command("notes", cls=StudyCommand)
@click.argument("recording", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--dof",
    type=click.Choice(["translation", "rotation"]),
    required=True,
    help="Which degree of freedom the recording is of.",
)
@json_option("The identified parameters, or the ramp's measures, as JSON.")
@out_dir_option("Also draw the fit: a chirp's Bode plot (notes_identify_bode.png).", required=False)
def notes(recording: Path, dof: str, json_path: Path, out_dir: Path | None) -> None:
    """Fit Fig. 8's model to a chirp, or measure a clamped ramp, from RECORDING.csv.

    Columns t, f_des and x (open end) or f_ee (clamped), SI units (rotation: N m, rad).

    \b
    Example:
      study identify notes chirp.csv --dof translation --json fit.json
    """
    # lazy: teleop_core.files costs 4 ms at start-up
    from teleop_core.files import write_atomically

    # lazy: teleop_core.notes.characterize (with scipy, pandas, pyarrow) costs 1.1 s at start-up
    from teleop_core.notes.characterize import identify_recording

    # lazy: teleop_core.notes.params costs 6 ms at start-up
    from teleop_core.notes.params import default_params

    # lazy: teleop_core.notes.recording (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.notes.recording import NotesRecording, NotesRecordingError

    # lazy: teleop_core.recording_checks (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.recording_checks import check_varies

    check_parent_folder(json_path)
    if out_dir is not None and out_dir.exists() and not out_dir.is_dir():
        raise StudyInputError(f"--out {out_dir} is a file; expected a folder")
    rec = NotesRecording.from_csv(recording)
    measured = "x" if rec.boundary == "open" else "f_ee"
    check_varies(
        {"f_des": rec.f_des, measured: rec.y},
        ("f_des", measured),
        f"recording {recording}",
        NotesRecordingError,
    )
    found, chirp = identify_recording(rec, default_params(dof).linear, dof)
    result: dict[str, Any] = {"dof": dof, "recording": str(recording), **found}
    write_atomically(json_path, json.dumps(result, indent=2) + "\n")
    if out_dir is not None and chirp is not None:
        from study.analysis.figures import save
        from study.analysis.notes_figures import bode

        out_dir.mkdir(parents=True, exist_ok=True)
        save(bode([chirp]), out_dir, "notes_identify_bode", ["png"])
    if "parameters" in result:
        fit = ", ".join(f"{k} {v:.4g}" for k, v in result["parameters"].items())
        click.echo(
            f"{dof} {rec.experiment} ({rec.boundary}): {fit}; "
            f"bandwidth {result['bandwidth_hz']:.2f} Hz"
        )
    else:
        ramp = result["ramp"]
        click.echo(
            f"{dof} ramp: max continuous {ramp['max_continuous']:.5g}, hysteresis "
            f"{ramp['hysteresis']:.3g}, asymmetry {ramp['asymmetry']:.1%}"
        )
    click.echo(f"json: {json_path}")
