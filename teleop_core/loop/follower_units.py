"""The real follower: a drive unit pushing the guidewire into a physical phantom, and the
lab's force sensors.

[endovascular], IV-A and IV-D: the guidewire drive is an ESP32 unit like the dial's (its
`drive` role: a speed command `W`, the measured q-current and speed in its state
line); the proximal reference force (a load cell at the insertion point) and the distal
force (the phantom's sensor under the tip) come from the lab's instruments. With these
in the loop (`PhysicalFollower`, handed to `TeleopLoop` through the hardware driver),
the follower's samples are measured, not simulated: at each acquisition the loop sends
the drive the speed command the follower received over the link, feeds the drive's
measured current and speed to the force estimator (the one the simulated follower
uses), and stores the sensors' forces. No simulated "true" force is made.

The forces come from a serial unit speaking `hardware`'s protocol in its `forces` role
(``HELLO`` -> ``OK forces <firmware>``, ``F`` -> ``F <t_ms> <proximal_N> <distal_N>``):
firmware on the amplifier's microcontroller, or a bridge from the lab's amplifier.
`EmulatedForceUnit` serves it on a pty for tests and trials without the sensors.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from teleop_core.loop.emulator import PtyUnit
from teleop_core.loop.hardware import (
    CorruptLine,
    Esp32Unit,
    HardwareError,
    UnitState,
)

__all__ = [
    "EmulatedForceUnit",
    "FollowerReading",
    "ForceReading",
    "ForceSource",
    "ForceUnit",
    "PhysicalFollower",
]

MAX_FORCE_N = 50.0
"""Beyond any force a guidewire drive or a phantom's sensor reads, N; a larger value in
a forces line is treated as corrupt (the XOR checksum misses some double errors)."""


@dataclass(frozen=True)
class ForceReading:
    """One forces line: the unit's clock and the two forces."""

    t_ms: float
    proximal_n: float
    distal_n: float

    @classmethod
    def parse(cls, payload: str) -> ForceReading:
        fields = payload.split()
        if len(fields) != 4 or fields[0] != "F":
            raise CorruptLine(f"expected a forces line 'F t proximal distal', got {payload!r}")
        try:
            values = [float(f) for f in fields[1:]]
        except ValueError:
            raise CorruptLine(f"non-numeric field in forces line {payload!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise CorruptLine(f"non-finite value in forces line {payload!r}")
        if any(abs(v) > MAX_FORCE_N for v in values[1:]):
            raise CorruptLine(
                f"implausible force in forces line {payload!r}; expected |F| <= {MAX_FORCE_N:g} N"
            )
        return cls(*values)


class ForceSource(Protocol):
    """Where the real follower's forces come from: a `ForceUnit`, or an LSL stream
    (`study.lsl.forces`). `read` raises `HardwareError` when the source is silent or
    gone."""

    name: str
    """What the trial's summary names it by (a unit's firmware, a stream's name)."""

    @property
    def corrupt_lines(self) -> int: ...

    def read(self) -> ForceReading: ...

    def close(self) -> None: ...


class ForceUnit:
    """The lab's force sensors behind one serial unit (`forces` role)."""

    def __init__(self, unit: Esp32Unit) -> None:
        self.unit = unit
        self.name = unit.firmware
        self.readings = 0

    @property
    def corrupt_lines(self) -> int:
        return self.unit.corrupt_lines

    @classmethod
    def open(cls, port: str, baudrate: int = 115200) -> ForceUnit:
        return cls(Esp32Unit(port, "forces", baudrate))

    def read(self) -> ForceReading:
        reading = self.unit._retrying("F", ForceReading.parse)
        self.readings += 1
        return reading

    def close(self) -> None:
        try:
            self.unit._serial.close()
        except OSError:
            pass  # an unplugged port


@dataclass(frozen=True)
class FollowerReading:
    """What the real follower measured at one acquisition."""

    drive: UnitState
    """The drive's state line: its wheel angle (rad), speed (rad/s), q-current (mA)."""
    forces: ForceReading


class PhysicalFollower:
    """The drive unit and the force sensors, as the loop's follower.

    `exchange(speed)` sends the drive its speed command and reads both; `inputs` keeps
    every (t_s, I_q in A, speed in rad/s) handed to the estimator, in order.
    """

    def __init__(self, drive: Esp32Unit, forces: ForceSource) -> None:
        if drive.role != "drive":
            raise HardwareError(f"the unit on {drive.port} is a {drive.role!r}; expected 'drive'")
        self.drive, self.forces = drive, forces
        self.inputs: list[tuple[float, float, float]] = []

    @classmethod
    def open(
        cls,
        drive_port: str,
        forces: str | Callable[[], ForceSource],
        baudrate: int = 115200,
    ) -> PhysicalFollower:
        """The drive on `drive_port` and the forces: a forces unit's port, or a function
        that opens another source."""
        drive = Esp32Unit(drive_port, "drive", baudrate)
        try:
            source = ForceUnit.open(forces, baudrate) if isinstance(forces, str) else forces()
        except BaseException:
            drive.close()
            raise
        return cls(drive, source)

    def exchange(self, t_s: float, speed_cmd_rad_s: float) -> FollowerReading:
        """Command the drive's speed (rad/s); its state and the sensors' forces."""
        state = self.drive.set_speed(speed_cmd_rad_s)
        reading = FollowerReading(state, self.forces.read())
        self.inputs.append((t_s, state.iq_ma / 1000.0, state.speed_rad_s))  # mA -> A
        return reading

    def record(self) -> dict[str, str | int]:
        return {
            "follower": "drive unit",
            "phantom": "physical",
            "forces": "measured",
            "drive_firmware": self.drive.firmware,
            "drive_corrupt_lines": self.drive.corrupt_lines,
            "drive_state_lines": len(self.inputs),
            "force_sensor_firmware": self.forces.name,
            "force_corrupt_lines": self.forces.corrupt_lines,
        }

    def close(self) -> None:
        self.drive.close()  # STOP: the wheel stands still
        self.forces.close()


class EmulatedForceUnit(PtyUnit):
    """A forces unit on a pty: the two forces follow functions of the unit's clock,
    which advances `period_ms` per line; `silent` stops its answers; `close` unplugs it.
    """

    def __init__(
        self,
        proximal: Callable[[float], float] = lambda t_s: 0.0,
        distal: Callable[[float], float] = lambda t_s: 0.0,
        firmware: str = "emu-1",
        period_ms: float = 10.0,
    ) -> None:
        super().__init__()
        self.proximal, self.distal, self.firmware = proximal, distal, firmware
        self.period_ms = period_ms
        self.t_ms = 0.0
        self.sent: list[tuple[float, float, float]] = []
        """Every (t_ms, proximal_N, distal_N) answered, as sent (rounded to the line)."""

    def _reply(self, payload: str) -> str:
        if payload == "HELLO":
            self.t_ms = 0.0
            return f"OK forces {self.firmware}"
        if payload == "F":
            t_s = self.t_ms / 1000.0
            line = f"F {self.t_ms:.0f} {self.proximal(t_s):.4f} {self.distal(t_s):.4f}"
            self.sent.append(tuple(float(v) for v in line.split()[1:]))  # type: ignore[arg-type]
            self.t_ms += self.period_ms
            return line
        if payload == "STOP":
            return "OK STOP"
        return f"E unknown command: '{payload}'"

    def _bad_checksum(self, payload: str, received: str) -> str:
        return "E checksum mismatch"
