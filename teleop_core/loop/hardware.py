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
``HELLO``                         ``OK <role> <firmware>``; role is ``dial`` or ``drive``
``I <current_mA>``                ``S ...`` state line (dial unit: q-current command)
``W <speed_rad_s>``               ``S ...`` state line (drive unit: speed command)
``Q``                             ``S ...`` state line (query only)
``STOP``                          ``OK STOP`` (commands zeroed)
                                  ``E <message>`` for a line it cannot accept

State line: ``S <t_ms> <angle_rad> <speed_rad_s> <iq_mA> <joystick>`` with the unit's
clock in ms, the unwrapped AS5600 angle, the firmware's speed estimate, the measured
q-axis current and (dial unit) the rotation joystick's axis in [-1, 1] (0 on a drive).

The host sends one command per driver update (100 Hz) and waits for the reply, so a
unit that stops answering is noticed within `timeout_s`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import serial

from teleop_core.loop.drivers import Driver, HandAction, OperatorView

PROTOCOL_VERSION = 1


class HardwareError(RuntimeError):
    """The unit did not answer, or answered something the protocol does not allow."""


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
        raise HardwareError(f"non-ASCII line from the unit: {line!r}") from None
    payload, sep, received = text.rpartition("*")
    if not sep or len(received) != 2:
        raise HardwareError(f"line without a checksum from the unit: {text!r}")
    if checksum(payload) != received.upper():
        raise HardwareError(
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

    @classmethod
    def parse(cls, payload: str) -> UnitState:
        fields = payload.split()
        if len(fields) != 6 or fields[0] != "S":
            raise HardwareError(
                f"expected a state line 'S t angle speed iq joystick', got {payload!r}"
            )
        try:
            values = [float(f) for f in fields[1:]]
        except ValueError:
            raise HardwareError(f"non-numeric field in state line {payload!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise HardwareError(f"non-finite value in state line {payload!r}")
        return cls(*values)


class Esp32Unit:
    """One ESP32 motor unit on a serial port (a device path or a pyserial URL)."""

    def __init__(
        self,
        port: str,
        role: str,
        baudrate: int = 115200,
        timeout_s: float = 0.05,
    ) -> None:
        self.port = port
        self.timeout_s = timeout_s
        try:
            self._serial = serial.serial_for_url(port, baudrate=baudrate, timeout=timeout_s)
        except (serial.SerialException, ValueError) as exc:
            raise HardwareError(f"cannot open serial port {port}: {exc}") from None
        self.firmware = self.hello(role)

    def _request(self, payload: str) -> str:
        self._serial.write(encode(payload))
        line = self._serial.readline()
        if not line.endswith(b"\n"):
            raise HardwareError(
                f"no answer from the unit on {self.port} within {self.timeout_s * 1000:.0f} ms "
                f"to {payload!r}"
            )
        reply = decode(line)
        if reply.startswith("E "):
            raise HardwareError(f"the unit on {self.port} refused {payload!r}: {reply[2:]}")
        return reply

    def hello(self, role: str) -> str:
        reply = self._request("HELLO").split()
        if len(reply) < 3 or reply[0] != "OK":
            raise HardwareError(f"unexpected greeting from {self.port}: {' '.join(reply)!r}")
        if reply[1] != role:
            raise HardwareError(f"the unit on {self.port} is a {reply[1]!r}; expected {role!r}")
        return reply[2]

    def set_current(self, current_a: float) -> UnitState:
        """Command the q-axis current (A); the unit answers with its state."""
        return UnitState.parse(self._request(f"I {current_a * 1000.0:.4f}"))  # A -> mA

    def set_speed(self, speed_rad_s: float) -> UnitState:
        return UnitState.parse(self._request(f"W {speed_rad_s:.5f}"))

    def query(self) -> UnitState:
        return UnitState.parse(self._request("Q"))

    def stop(self) -> None:
        self._request("STOP")

    def close(self) -> None:
        try:
            self.stop()
        except HardwareError:
            pass  # closing anyway: the unit zeroes its command when the host goes quiet
        self._serial.close()


class HardwareDriver(Driver):
    """The real dial: a person turns it; the loop renders eq. 9 on its motor.

    The loop calls `exchange` at every driver update with the current Psi asks for and
    receives the dial's measured angle and speed; the rotation joystick on the same unit
    sets the guidewire's rotation rate.
    """

    physical_dial = True
    realtime = True

    def __init__(self, unit: Esp32Unit, max_rotation_rate_rad_s: float = math.pi / 2) -> None:
        self.unit = unit
        self.max_rotation_rate_rad_s = max_rotation_rate_rad_s
        self.last: UnitState | None = None

    @classmethod
    def open(cls, port: str, baudrate: int = 115200) -> HardwareDriver:
        return cls(Esp32Unit(port, "dial", baudrate))

    def exchange(self, current_cmd_a: float) -> UnitState:
        self.last = self.unit.set_current(current_cmd_a)
        return self.last

    def act(self, view: OperatorView) -> HandAction:
        joystick = 0.0 if self.last is None else max(min(self.last.joystick, 1.0), -1.0)
        return HandAction(rotation_rate_rad_s=joystick * self.max_rotation_rate_rad_s)

    def close(self) -> None:
        self.unit.close()
