"""The hardware driver: the real dial on its ESP32, over a serial line.

[endovascular], IV-A: one ESP32 unit per motor (2804 gimbal PMSM, DRV8313 driver, INA240
current sense, AS5600 encoder), joined to the host by a serial port. The line protocol
below is ours (the paper does not publish one); firmware that speaks it makes the real
dial a `Driver` like any other.

Protocol, version 1 (ASCII, 115200 baud 8N1 by default)
--------------------------------------------------------
Every line is ``<payload>*<HH>\\n`` where HH is the XOR of the payload's bytes in two
upper-case hex digits (as NMEA 0183 does). Fields are separated by one space; numbers
are decimal, SI except the current (mA, as the unit's firmware and eqs. 14-15 use it).

Host -> unit                      Unit -> host
``HELLO``                         ``OK <role> <firmware>``; role is ``dial``, ``drive`` or
                                  ``forces``
``I <current_mA>``                ``S ...`` state line (dial unit: q-current command)
``W <speed_rad_s>``               ``S ...`` state line (drive unit: speed command)
``Q``                             ``S ...`` state line (query only)
``STOP``                          ``OK STOP`` (commands zeroed)
``F``                             ``F <t_ms> <proximal_N> <distal_N>`` (a forces unit)
                                  ``E <message>`` for a line it cannot accept

State line: ``S <t_ms> <angle_rad> <speed_rad_s> <iq_mA> <joystick> [<button>]`` with
the unit's clock in ms, the unwrapped AS5600 angle, the firmware's speed estimate, the
measured q-axis current, (dial unit) the rotation joystick's axis in [-1, 1] and its
push button, 1 while held down (both 0 on a drive). The button field is optional (the
firmware sends it from 1.1.0; a line without it reads as the button up). With a
physical phantom, a press of the dial's button (up, then down, within the trial) ends
the trial as reached (`HardwareDriver.end`).
A forces unit (the lab's proximal load cell and the phantom's distal force sensor on one
serial line, `teleop_core.loop.follower_units`) answers ``F`` with its clock and the two
forces in N.

The host sends one command per driver update (100 Hz) and waits for the reply, so a
unit that stops answering is noticed within `timeout_s` (two update periods by default:
with the wait for the next update, within three periods of its last answer). A reply
that fails its checksum or does not parse is never used: the host drops what it has
read and sends the command once more (`corrupt_lines` counts these); a second bad reply
in a row, a unit that does not answer, or a port that goes away (the cable pulled) is a
`HardwareError`, which ends the trial (the session marks it interrupted).

The unit zeroes its command when the host goes quiet (its watchdog, 100 ms in the
firmware under `firmware/`, whose host build runs this protocol on a simulated motor).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar

import serial

from teleop_core.loop.drivers import Driver, DriverFailure, HandAction, OperatorView

T = TypeVar("T")

PROTOCOL_VERSION = 1
UPDATE_PERIOD_S = 0.01
"""The host's driver updates, one command each (100 Hz)."""
TIMEOUT_S = 2 * UPDATE_PERIOD_S
"""How long the host waits for a reply before it calls the unit silent."""
MAX_SHAFT_SPEED_RAD_S = 50.0
"""Faster than any shaft of a unit turns (a hand on the dial, the drive's 20 rad/s
limit): a state line whose angle moved faster since the last, or whose clock went
back, is treated as corrupt (the XOR checksum misses errors that flip the same bit in
two bytes)."""
UNIT_ROLES = ("dial", "drive", "forces")
"""What a unit's greeting may name it."""
GREETING_S = 2.0
"""How long the host greets a unit it has just opened before it gives up on it."""


class HardwareError(DriverFailure):
    """The unit did not answer, or answered something the protocol does not allow."""


class CorruptLine(HardwareError):
    """A reply that failed its checksum or did not parse."""


class UnitSilent(HardwareError):
    """No reply within the timeout."""


class UnitRefused(HardwareError):
    """The unit answered `E <message>`."""


class UnitGone(HardwareError):
    """The port went away (the cable pulled, the unit powered off)."""


def checksum(payload: str) -> str:
    """XOR of the payload's bytes as two upper-case hex digits.

    >>> checksum("Q")
    '51'
    """
    value = 0
    for byte in payload.encode("ascii"):
        value ^= byte
    return f"{value:02X}"


def encode(payload: str) -> bytes:
    """A protocol line for `payload`."""
    return f"{payload}*{checksum(payload)}\n".encode("ascii")


def decode(line: bytes) -> str:
    """The payload of a received line; HardwareError if it is malformed or corrupt."""
    try:
        text = line.decode("ascii").rstrip("\r\n")
    except UnicodeDecodeError:
        raise CorruptLine(f"non-ASCII line from the unit: {line!r}") from None
    payload, sep, received = text.rpartition("*")
    if not sep or len(received) != 2:
        raise CorruptLine(f"line without a checksum from the unit: {text!r}")
    if checksum(payload) != received.upper():
        raise CorruptLine(
            f"checksum mismatch in {text!r}: expected {checksum(payload)}, got {received}"
        )
    return payload


@dataclass(frozen=True)
class UnitState:
    """One state line."""

    t_ms: float
    angle_rad: float
    speed_rad_s: float
    iq_ma: float
    joystick: float
    button: bool = False
    """The dial's push button held down (False on a drive, or from older firmware)."""

    @classmethod
    def parse(cls, payload: str) -> UnitState:
        fields = payload.split()
        if len(fields) not in (6, 7) or fields[0] != "S":
            raise CorruptLine(
                f"expected a state line 'S t angle speed iq joystick [button]', got {payload!r}"
            )
        button = fields[6] if len(fields) == 7 else "0"
        if button not in ("0", "1"):
            raise CorruptLine(f"button field {button!r} in state line {payload!r}; expected 0 or 1")
        try:
            t_ms, angle_rad, speed_rad_s, iq_ma, joystick = (float(f) for f in fields[1:6])
        except ValueError:
            raise CorruptLine(f"non-numeric field in state line {payload!r}") from None
        if not all(math.isfinite(v) for v in (t_ms, angle_rad, speed_rad_s, iq_ma, joystick)):
            raise CorruptLine(f"non-finite value in state line {payload!r}")
        return cls(t_ms, angle_rad, speed_rad_s, iq_ma, joystick, button=button == "1")


class JoinedFollower(Protocol):
    """What the dial's driver asks of the follower that joins it (`follower_units`, which
    builds on this module): its record for the trial, and to close."""

    def record(self) -> dict[str, str | int]: ...

    def close(self) -> None: ...


class Esp32Unit:
    """One ESP32 motor unit on a serial port (a device path or a pyserial URL)."""

    def __init__(
        self,
        port: str,
        role: str | None,
        baudrate: int = 115200,
        timeout_s: float = TIMEOUT_S,
        greeting_s: float = GREETING_S,
    ) -> None:
        self.port = port
        self.timeout_s = timeout_s
        self.corrupt_lines = 0
        """Replies dropped for a failed checksum, an unparsable field or an implausible
        state (each re-sent)."""
        self.last_state: UnitState | None = None
        try:
            self._serial = serial.serial_for_url(port, baudrate=baudrate, timeout=timeout_s)
        except (serial.SerialException, ValueError) as exc:
            raise HardwareError(f"cannot open serial port {port}: {exc}") from None
        try:
            self.role, self.firmware = self._greet(greeting_s)
            if role is not None and self.role != role:
                raise HardwareError(
                    f"the unit on {self.port} is a {self.role!r}; expected {role!r}"
                )
        except HardwareError:
            self._serial.close()
            raise

    def _exchange(self, payload: str) -> bytes:
        """Send one line and read one back; HardwareError when the port is gone or the
        unit is silent."""
        try:
            self._serial.write(encode(payload))
            line = self._serial.readline()
        except (serial.SerialException, OSError) as exc:
            raise UnitGone(
                f"the unit on {self.port} is gone (unplugged or powered off?): {exc}"
            ) from None
        if not line.endswith(b"\n"):
            raise UnitSilent(
                f"no answer from the unit on {self.port} within {self.timeout_s * 1000:.0f} ms "
                f"to {payload!r}"
            )
        return line

    def _request(self, payload: str) -> str:
        """The unit's reply to `payload` (checked, not an `E`)."""
        return self._retrying(payload, str)

    def _retrying(self, payload: str, parse: Callable[[str], T]) -> T:
        """The unit's reply to `payload`, parsed; a corrupt reply is dropped and the
        line sent once more."""
        try:
            return self._parsed(self._exchange(payload), payload, parse)
        except CorruptLine:
            self.corrupt_lines += 1
            self._drain()
        try:
            return self._parsed(self._exchange(payload), payload, parse)
        except CorruptLine as exc:
            self.corrupt_lines += 1
            raise HardwareError(
                f"two corrupt replies in a row from the unit on {self.port}: {exc}"
            ) from None

    def _parsed(self, line: bytes, payload: str, parse: Callable[[str], T]) -> T:
        reply = decode(line)
        if reply.startswith("E "):
            raise UnitRefused(f"the unit on {self.port} refused {payload!r}: {reply[2:]}")
        return parse(reply)

    def _drain(self) -> None:
        """Drop whatever else is on the line (the rest of a garbled reply)."""
        try:
            self._serial.reset_input_buffer()
        except (serial.SerialException, OSError):
            pass  # the next exchange reports a port that has gone

    def _greet(self, wait_s: float) -> tuple[str, str]:
        """HELLO until the unit answers (an ESP32 that the port's opening reset boots
        for about a second, and prints its boot log first); its (role, firmware)."""
        deadline = time.monotonic() + wait_s
        while True:
            self._drain()  # what the unit sent before we listened
            try:
                reply = self._parsed(self._exchange("HELLO"), "HELLO", str).split()
                break
            except (UnitSilent, CorruptLine) as exc:
                if time.monotonic() >= deadline:
                    raise UnitSilent(
                        f"no greeting from the unit on {self.port} within {wait_s:.1f} s ({exc})"
                    ) from None
        if len(reply) != 3 or reply[0] != "OK" or reply[1] not in UNIT_ROLES:
            raise HardwareError(f"unexpected greeting from {self.port}: {' '.join(reply)!r}")
        return reply[1], reply[2]

    def _state(self, payload: str) -> UnitState:
        """A state line, checked against the last one (`MAX_SHAFT_SPEED_RAD_S`)."""
        state = UnitState.parse(payload)
        last = self.last_state
        if last is not None:
            dt_s = (state.t_ms - last.t_ms) / 1000.0
            reach = MAX_SHAFT_SPEED_RAD_S * max(dt_s, UPDATE_PERIOD_S)
            if dt_s < 0 or abs(state.angle_rad - last.angle_rad) > reach:
                raise CorruptLine(
                    f"implausible state line {payload!r} after t = {last.t_ms:.0f} ms, "
                    f"angle {last.angle_rad:.4f} rad"
                )
        self.last_state = state
        return state

    def set_current(self, current_a: float) -> UnitState:
        """Command the q-axis current (A); the unit answers with its state."""
        return self._retrying(f"I {current_a * 1000.0:.4f}", self._state)  # A -> mA

    def set_speed(self, speed_rad_s: float) -> UnitState:
        """Command the shaft speed (rad/s) of a drive unit; it answers with its state."""
        return self._retrying(f"W {speed_rad_s:.5f}", self._state)

    def query(self) -> UnitState:
        return self._retrying("Q", self._state)

    def stop(self) -> None:
        self._request("STOP")

    def close(self) -> None:
        try:
            self.stop()
        except HardwareError:
            pass  # closing anyway: the unit zeroes its command when the host goes quiet
        try:
            self._serial.close()
        except (serial.SerialException, OSError):
            pass  # an unplugged port


class HardwareDriver(Driver):
    """The real dial: a person turns it; the loop renders eq. 9 on its motor.

    The loop calls `exchange` at every driver update with the current Psi asks for and
    receives the dial's measured angle and speed; the rotation joystick on the same unit
    sets the guidewire's rotation rate. `follower`, given, is the real follower (the
    drive unit and the force sensors, a `teleop_core.loop.follower_units.PhysicalFollower`,
    held here untyped so that this module, which that one builds on, does not import it),
    which the loop then uses in place of its simulated follower and phantom.

    With a physical phantom nothing in the loop sees the tip, so a person decides that
    it reached the target: a press of the dial's button (seen up, then down, within the
    trial: a button still held from the last trial does not end this one), or the
    experimenter's `reach()` from another thread. Either ends the trial at the next
    driver update, `end` naming which ("button" or "experimenter"). A simulated phantom
    decides for itself; the button is then ignored.
    """

    physical_dial = True
    realtime = True

    def __init__(
        self,
        unit: Esp32Unit,
        max_rotation_rate_rad_s: float = math.pi / 2,
        follower: JoinedFollower | None = None,
    ) -> None:
        self.unit = unit
        self.max_rotation_rate_rad_s = max_rotation_rate_rad_s
        self.follower = follower
        self.last: UnitState | None = None
        self.end: str | None = None
        """Who ended the trial as reached: "button", "experimenter", or None."""
        self._button_up = False
        self._reached = threading.Event()

    @classmethod
    def open(cls, port: str, baudrate: int = 115200) -> HardwareDriver:
        return cls(Esp32Unit(port, "dial", baudrate))

    def exchange(self, current_cmd_a: float) -> UnitState:
        self.last = self.unit.set_current(current_cmd_a)
        return self.last

    def reach(self) -> None:
        """The experimenter saw the tip reach the target (any thread): with a physical
        phantom the trial ends, as reached, at the next driver update."""
        self._reached.set()

    def act(self, view: OperatorView) -> HandAction:
        joystick = 0.0 if self.last is None else max(min(self.last.joystick, 1.0), -1.0)
        rate = joystick * self.max_rotation_rate_rad_s
        if self.follower is None or self.last is None:
            return HandAction(rotation_rate_rad_s=rate)
        if self.last.button and self._button_up and self.end is None:
            self.end = "button"
        self._button_up = self._button_up or not self.last.button
        if self._reached.is_set() and self.end is None:
            self.end = "experimenter"
        return HandAction(rotation_rate_rad_s=rate, done=self.end is not None)

    def record(self) -> dict[str, str | int]:
        follower = self.follower.record() if self.follower is not None else {}
        return {
            "dial_firmware": self.unit.firmware,
            "dial_corrupt_lines": self.unit.corrupt_lines,
            **follower,
        }

    def close(self) -> None:
        try:
            self.unit.close()
        finally:
            if self.follower is not None:
                self.follower.close()
