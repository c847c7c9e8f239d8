"""A unit's connection check: who answers on a port, how fast, and what it measures.

`check_unit` greets the unit (its role and firmware), then queries it at the host's
update rate for a few seconds while the person turns the dial and the joystick, timing
every round trip, and summarises what came back: the state lines' rate, the unit's
clock against the host's, the encoder's range and smallest step (an AS5600 reads whole
counts of 2 pi / 4096), the measured current at no command (its offset and noise),
the joystick's range and the presses of its button. `UnitCheck.problems` lists what
fails the check; a unit that does not answer at all raises `HardwareError` before
anything is measured.

A drive can be spun at a small speed for the check (`spin_rad_s`); nothing moves a
motor unless asked to.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from teleop_core.loop.hardware import UPDATE_PERIOD_S, Esp32Unit, HardwareError, UnitState
from teleop_core.loop.host_unit import HOST_SUFFIX

ENCODER_COUNTS = 4096
"""AS5600: 12 bits per turn."""
ROUND_TRIP_TARGET_MS = 2.0
"""A command's state back within this, median (the loop's < 5 ms end-to-end budget
leaves the rest to the estimator and the rendering)."""
MIN_RATE_FRACTION = 0.95
"""State lines per second at least this fraction of the rate asked for."""
CLOCK_TOLERANCE = 0.05
"""The unit's clock within this fraction of the host's."""


@dataclass
class UnitCheck:
    """What a check of one unit found."""

    port: str
    role: str
    firmware: str
    simulated: bool
    """The host build of the firmware (a simulated motor), not hardware."""
    seconds: float
    lines: int
    corrupt_lines: int
    round_trip_ms_median: float
    round_trip_ms_p95: float
    round_trip_ms_max: float
    line_rate_hz: float
    asked_rate_hz: float
    clock_ratio: float
    """The unit's clock over the host's during the check (1 when they agree)."""
    angle_min_rad: float
    angle_max_rad: float
    angle_step_rad: float
    """The smallest change of angle seen (nan when the encoder did not move)."""
    speed_max_rad_s: float
    current_mean_ma: float
    current_sd_ma: float
    joystick_min: float
    joystick_max: float
    button_presses: int
    """Presses of the dial's button seen (up, then down) during the check."""
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.problems

    def to_dict(self) -> dict[str, object]:
        return {**asdict(self), "passed": self.passed}


def check_unit(
    port: str,
    role: str | None = None,
    seconds: float = 3.0,
    spin_rad_s: float = 0.0,
    on_state: Callable[[float, UnitState], None] = lambda t, s: None,
    baudrate: int = 115200,
) -> UnitCheck:
    """Check the unit on `port` (of `role`, if given) for `seconds`.

    Parameters
    ----------
    port : str
        A serial device or pyserial URL.
    role : {"dial", "drive"} or None
        The role expected; None takes whichever answers.
    seconds : float
        How long to query at the host's update rate (100 Hz), s.
    spin_rad_s : float
        A drive's speed command during the check, rad/s (0: it stays still).
    on_state : callable
        Told every state (host time since the start in s, the state), for a live line.

    Raises
    ------
    HardwareError
        Nothing answers on the port, or it answers what the protocol does not allow.
    """
    unit = Esp32Unit(port, role, baudrate)
    if unit.role == "forces":
        unit.close()
        raise HardwareError(
            f"the unit on {port} is a forces unit (firmware {unit.firmware}); this check "
            "is for a dial or a drive, a session reads a forces unit through the design's "
            "[sensors] table"
        )
    try:
        states, round_trips, host_s = _query(unit, seconds, spin_rad_s, on_state)
    finally:
        unit.close()
    return _summary(unit, states, np.asarray(round_trips) * 1000.0, host_s, seconds)


def _query(
    unit: Esp32Unit,
    seconds: float,
    spin_rad_s: float,
    on_state: Callable[[float, UnitState], None],
) -> tuple[list[UnitState], list[float], float]:
    """Query `unit` every update period for `seconds`; the states, the round trips (s)
    and the host's time over the states' span (s)."""
    states: list[UnitState] = []
    round_trips: list[float] = []
    start = time.monotonic()
    n = max(round(seconds / UPDATE_PERIOD_S), 2)
    first_s = last_s = 0.0
    for k in range(n):
        wait = start + k * UPDATE_PERIOD_S - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        sent = time.perf_counter()
        if unit.role == "drive":
            state = unit.set_speed(spin_rad_s)
        else:
            state = unit.set_current(0.0)
        round_trips.append(time.perf_counter() - sent)
        last_s = time.monotonic() - start
        if k == 0:
            first_s = last_s
        states.append(state)
        on_state(last_s, state)
    if unit.role == "drive" and spin_rad_s:
        unit.set_speed(0.0)
    return states, round_trips, last_s - first_s


def _summary(
    unit: Esp32Unit,
    states: list[UnitState],
    round_trips_ms: np.ndarray,
    host_s: float,
    seconds: float,
) -> UnitCheck:
    t_ms = np.array([s.t_ms for s in states])
    angle = np.array([s.angle_rad for s in states])
    iq = np.array([s.iq_ma for s in states])
    joystick = np.array([s.joystick for s in states])
    button = [s.button for s in states]
    steps = np.abs(np.diff(angle))
    steps = steps[steps > 1e-9]
    check = UnitCheck(
        port=unit.port,
        role=unit.role,
        firmware=unit.firmware,
        simulated=unit.firmware.endswith(HOST_SUFFIX),
        seconds=seconds,
        lines=len(states),
        corrupt_lines=unit.corrupt_lines,
        round_trip_ms_median=float(np.median(round_trips_ms)),
        round_trip_ms_p95=float(np.percentile(round_trips_ms, 95)),
        round_trip_ms_max=float(round_trips_ms.max()),
        line_rate_hz=(len(states) - 1) / host_s if host_s > 0 else math.nan,
        asked_rate_hz=1.0 / UPDATE_PERIOD_S,
        clock_ratio=float((t_ms[-1] - t_ms[0]) / 1000.0 / host_s) if host_s > 0 else math.nan,
        angle_min_rad=float(angle.min()),
        angle_max_rad=float(angle.max()),
        angle_step_rad=float(steps.min()) if len(steps) else math.nan,
        speed_max_rad_s=float(np.abs([s.speed_rad_s for s in states]).max()),
        current_mean_ma=float(iq.mean()),
        current_sd_ma=float(iq.std(ddof=1)),
        joystick_min=float(joystick.min()),
        joystick_max=float(joystick.max()),
        button_presses=sum(1 for a, b in itertools.pairwise(button) if b and not a),
    )
    _judge(check)
    return check


def _judge(check: UnitCheck) -> None:
    """Fill in what fails the check (`problems`) and what is worth knowing (`notes`)."""
    if check.round_trip_ms_median > ROUND_TRIP_TARGET_MS:
        check.problems.append(
            f"round trip {check.round_trip_ms_median:.2f} ms (median); expected under "
            f"{ROUND_TRIP_TARGET_MS:g} ms (a USB hub, a Bluetooth serial link or a busy "
            "host slows it)"
        )
    if not check.line_rate_hz >= MIN_RATE_FRACTION * check.asked_rate_hz:
        check.problems.append(
            f"{check.line_rate_hz:.1f} state lines per s; expected at least "
            f"{MIN_RATE_FRACTION * check.asked_rate_hz:.0f} of the "
            f"{check.asked_rate_hz:.0f} asked for"
        )
    if not abs(check.clock_ratio - 1.0) <= CLOCK_TOLERANCE:
        check.problems.append(
            f"the unit's clock ran at {check.clock_ratio:.3f} of the host's; expected "
            f"1 within {CLOCK_TOLERANCE:.0%} (a unit that restarted during the check?)"
        )
    if check.corrupt_lines:
        check.problems.append(
            f"{check.corrupt_lines} corrupt line(s); expected none (the cable, its "
            "length, or the baud rate)"
        )
    if check.role == "dial" and not check.button_presses:
        check.notes.append(
            "the button was not pressed: press it during the check to see it read (a "
            "physical phantom's trials end at its press)"
        )
    count_rad = 2 * math.pi / ENCODER_COUNTS
    if math.isnan(check.angle_step_rad):
        check.notes.append(
            "the encoder did not move: turn the dial during the check to see it count"
            if check.role == "dial"
            else "the encoder did not move (give --spin to turn the drive)"
        )
    elif check.angle_step_rad < 0.5 * count_rad:
        check.notes.append(
            f"angle steps of {check.angle_step_rad * 1000:.3f} mrad, finer than the "
            f"AS5600's count ({count_rad * 1000:.3f} mrad): a filtered angle"
        )
