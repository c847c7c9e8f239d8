"""`study characterize notes`: the NOTES device's characterisation ([notes], III)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click
from rich.console import Console

from study.commands.base import (
    SEED,
    StudyCommand,
    StudyGroup,
    check_parent_folder,
    json_option,
    out_dir_option,
)
from study.errors import StudyInputError


@click.group("characterize", cls=StudyGroup)
def characterize() -> None:
    """Characterise a haptic device: static ramps, chirps, grey-box fit, compensation.

    \b
    Example:
      study characterize notes --json notes.json --out notes/
    """


@characterize.command("notes", cls=StudyCommand)
@json_option("Write the numbers here (keys translation and rotation).")
@out_dir_option("Folder for the Bode and hysteresis figures and the compensation table.")
@click.option(
    "--noise",
    type=click.FloatRange(min=0, max=0.5),
    default=0.0,
    show_default=True,
    help="Sensor noise as a fraction of each signal's standard deviation.",
)
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seeds the noise.")
def notes(json_path: Path, out_dir: Path, noise: float, seed: int) -> None:
    """Run the paper's ramps and 1-30 Hz chirps on the simulated NOTES device, fit Fig. 8's
    model, and compare the ramps with and without the friction/direction compensator.

    \b
    Example:
      study characterize notes --json notes.json --out notes/
    """
    # lazy: study.analysis.figures (with pandas, pyarrow, matplotlib) costs 0.7 s at start-up
    from study.analysis.figures import save

    # lazy: study.analysis.notes_figures (with scipy, pandas, pyarrow) costs 1.5 s at start-up
    from study.analysis.notes_figures import bode, compensation_table, ramp_hysteresis

    # lazy: teleop_core.files costs 5 ms at start-up
    from teleop_core.files import write_atomically

    # lazy: teleop_core.follower.recording (with pandas, pyarrow, numpy) costs 0.3 s at start-up
    from teleop_core.follower.recording import write_csv_atomically

    # lazy: teleop_core.notes.characterize (with scipy, pandas, pyarrow) costs 1.1 s at start-up
    from teleop_core.notes.characterize import characterize_simulated

    # lazy: teleop_core.notes.params costs 5 ms at start-up
    from teleop_core.notes.params import DOFS, default_params

    check_parent_folder(json_path)
    if out_dir.exists() and not out_dir.is_dir():
        raise StudyInputError(f"--out {out_dir} is a file; expected a folder")
    results = []
    with Console(stderr=True).status("characterising") as status:
        for dof in DOFS:
            status.update(f"characterising {dof}: ramps, chirps, fit")
            results.append(characterize_simulated(default_params(dof), noise, seed))
    out_dir.mkdir(parents=True, exist_ok=True)
    table = compensation_table(results)
    write_csv_atomically(table, out_dir / "compensation.csv")
    save(bode(results), out_dir, "notes_bode", ["png", "pdf"])
    save(ramp_hysteresis(results), out_dir, "notes_ramp_compensation", ["png", "pdf"])
    payload = {ch.dof: ch.to_dict() for ch in results}
    write_atomically(json_path, json.dumps(payload, indent=2, default=_finite) + "\n")
    for ch in results:
        hysteresis, asymmetry = f"{ch.before.hysteresis:.3g}", f"{ch.before.asymmetry:.1%}"
        if ch.after is not None:  # the compensated ramp (every simulated axis has one)
            hysteresis += f" -> {ch.after.hysteresis:.3g}"
            asymmetry += f" -> {ch.after.asymmetry:.1%}"
        click.echo(
            f"{ch.dof}: bandwidth {ch.bandwidth_hz:.2f} Hz, settling {ch.settling_time_s:.3f} s, "
            f"max continuous {ch.before.max_continuous:.5g}, hysteresis {hysteresis}, "
            f"asymmetry {asymmetry}"
        )
    click.echo(f"json: {json_path}; figures and compensation.csv: {out_dir}")


def _finite(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    raise TypeError(f"not JSON serialisable: {value!r}")
