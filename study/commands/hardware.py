"""`study hardware check`: is the unit on a port the study's, and does it measure?"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click

from study.commands.base import StudyGroup, write_json_atomically
from study.errors import StudyInputError

if TYPE_CHECKING:
    from teleop_core.loop.hardware import UnitState
    from teleop_core.loop.unit_check import UnitCheck


@click.group("hardware", cls=StudyGroup)
def hardware() -> None:
    """The motor units on their serial ports: check one before a session.

    \b
    Example:
      study hardware check --port /dev/ttyUSB0 --role dial
    """


@hardware.command("check")
@click.option("--port", required=True, help="The unit's serial port, e.g. /dev/ttyUSB0 or COM3.")
@click.option(
    "--role",
    type=click.Choice(["dial", "drive"]),
    default=None,
    help="The role the unit must have [default: whichever answers].",
)
@click.option(
    "--seconds",
    type=click.FloatRange(0.5, 60.0),
    default=3.0,
    show_default=True,
    help="How long to read the unit at 100 Hz (turn the dial and the joystick, press its "
    "button meanwhile).",
)
@click.option(
    "--spin",
    "spin_rad_s",
    type=click.FloatRange(-20.0, 20.0),
    default=0.0,
    show_default=True,
    help="A drive's speed during the check, rad/s (the wheel turns; 0 keeps it still).",
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the check's figures to this JSON file.",
)
def check(
    port: str, role: str | None, seconds: float, spin_rad_s: float, json_path: Path | None
) -> None:
    """Greet the unit on --port (its role and firmware), read it at the host's 100 Hz for
    --seconds (round-trip time, state line rate, the unit's clock, encoder, current and
    joystick readings) and say whether it is fit for a session; exit status 2 if not.

    \b
    Example:
      study hardware check --port /dev/ttyUSB0 --role dial
    """
    # lazy: teleop_core.loop.hardware (with serial, numpy) costs 74 ms at start-up
    from teleop_core.loop.hardware import HardwareError

    # lazy: teleop_core.loop.unit_check (with serial, numpy) costs 84 ms at start-up
    from teleop_core.loop.unit_check import check_unit

    if spin_rad_s and role != "drive":
        raise StudyInputError(f"--spin {spin_rad_s:g} needs --role drive; a dial is not spun")
    live = _LiveLine(sys.stderr.isatty())
    if live.tty:
        click.echo(
            f"unit on {port}: greeting it; turn the dial and the joystick, press its button",
            err=True,
        )
    try:
        result = check_unit(port, role, seconds, spin_rad_s, on_state=live)
    except HardwareError as exc:
        raise StudyInputError(
            f"--port {port}: {exc}; expected a unit running the study's firmware "
            "(see the hardware tutorial: wiring, `pio run -t upload`)"
        ) from None
    live.end()
    for line in _report(result):
        click.echo(line)
    if json_path is not None:
        write_json_atomically(result.to_dict(), json_path)
    if not result.passed:
        raise StudyInputError(f"--port {port}: check failed: " + "; ".join(result.problems))
    click.echo("check passed")


class _LiveLine:
    """The unit's readings once a second while the check runs (on a terminal, in place)."""

    def __init__(self, tty: bool) -> None:
        self.tty, self.next_s = tty, 1.0

    def __call__(self, t_s: float, state: UnitState) -> None:
        if t_s < self.next_s:
            return
        self.next_s += 1.0
        line = (
            f"  {t_s:4.1f} s: angle {state.angle_rad:+8.4f} rad, speed "
            f"{state.speed_rad_s:+7.3f} rad/s, current {state.iq_ma:+8.3f} mA, joystick "
            f"{state.joystick:+.2f}"
        )
        click.echo(("\r" + line) if self.tty else line, err=True, nl=not self.tty)

    def end(self) -> None:
        if self.tty:
            click.echo("", err=True)


def _report(result: UnitCheck) -> list[str]:
    """The check's figures as lines."""
    kind = (
        "the firmware's host build: a simulated motor, not hardware"
        if result.simulated
        else "hardware"
    )
    step = (
        "did not move"
        if math.isnan(result.angle_step_rad)
        else f"smallest step {result.angle_step_rad * 1000:.3f} mrad "
        f"(an AS5600 count: {2 * math.pi / 4096 * 1000:.3f} mrad)"
    )
    lines = [
        f"unit: {result.role}, firmware {result.firmware} ({kind}) on {result.port}",
        f"round trip: median {result.round_trip_ms_median:.2f} ms, 95th percentile "
        f"{result.round_trip_ms_p95:.2f} ms, max {result.round_trip_ms_max:.2f} ms over "
        f"{result.lines} commands",
        f"state lines: {result.line_rate_hz:.1f} per s (asked for "
        f"{result.asked_rate_hz:.0f}); the unit's clock ran at {result.clock_ratio:.3f} "
        "of the host's",
        f"encoder: {result.angle_min_rad:+.4f} to {result.angle_max_rad:+.4f} rad, {step}; "
        f"speed up to {result.speed_max_rad_s:.3f} rad/s",
        f"current: mean {result.current_mean_ma:+.3f} mA, sd {result.current_sd_ma:.3f} mA "
        "(at no command: the current sense's offset and noise)",
    ]
    if result.role == "dial":
        lines.append(
            f"joystick: {result.joystick_min:+.2f} to {result.joystick_max:+.2f}; button "
            f"pressed {result.button_presses} time(s)"
        )
    lines += [f"note: {note}" for note in result.notes]
    return lines


__all__ = ["hardware"]
