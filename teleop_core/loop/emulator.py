"""An emulated ESP32 dial unit on a pseudo-terminal, speaking `hardware`'s protocol.

For tests and for trying the hardware path without the device: `EmulatedDialUnit`
opens a pty pair, serves the protocol from a thread on the master end, and exposes the
slave end's path as `port`, which `HardwareDriver.open(port)` opens like a USB serial
device. The dial's angle follows a script (a function of the unit's clock) as if a
person turned it; every current command is recorded. Faults can be switched on to
check the host's handling: a corrupt checksum (`corrupt_next`: True, or how many
replies in a row) or silence. `PtyUnit` is what every emulated unit shares (the pty
pair, the serving thread, the line framing and checksum); a unit says only what it
answers (`_reply`), as `follower_units.EmulatedForceUnit` does too.
"""

from __future__ import annotations

import math
import os
import threading
import tty
from collections.abc import Callable
from typing import Self

from teleop_core.loop.hardware import checksum, encode


class PtyUnit:
    """A unit on a pty: serves `_reply(payload)` for each checksummed line from a thread
    on the master end; `port` is the slave end's path; `silent` stops its answers;
    `close` (or leaving the `with`) unplugs it."""

    def __init__(self) -> None:
        self.silent = False
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)

    def __enter__(self) -> Self:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        os.close(self._master)
        os.close(self._slave)
        self._thread.join(timeout=1.0)

    def _reply(self, payload: str) -> str:
        raise NotImplementedError

    def _bad_checksum(self, payload: str, received: str) -> str:
        """The answer to a line whose checksum does not match."""
        return f"E checksum {received!r} for {payload!r}"

    def _wire(self, line: bytes) -> bytes:
        """The encoded answer as it goes on the wire (a unit may garble it)."""
        return line

    def _serve(self) -> None:
        buffer = b""
        while not self._stop.is_set():
            try:
                chunk = os.read(self._master, 256)
            except OSError:
                return
            buffer += chunk
            while b"\n" in buffer:
                raw, buffer = buffer.split(b"\n", 1)
                text = raw.decode("ascii", "replace").rstrip("\r")
                payload, _, received = text.rpartition("*")
                if checksum(payload) != received:
                    reply = self._bad_checksum(payload, received)
                else:
                    reply = self._reply(payload)
                if self.silent:
                    continue
                try:
                    os.write(self._master, self._wire(encode(reply)))
                except OSError:
                    return


class EmulatedDialUnit(PtyUnit):
    """A dial unit on a pty. Its clock advances `period_ms` per state line it sends."""

    def __init__(
        self,
        angle: Callable[[float], float] = lambda t_s: 0.0,
        joystick: Callable[[float], float] = lambda t_s: 0.0,
        role: str = "dial",
        firmware: str = "emu-1",
        period_ms: float = 10.0,
    ) -> None:
        super().__init__()
        self.angle, self.joystick, self.role, self.firmware = angle, joystick, role, firmware
        self.period_ms = period_ms
        self.t_ms = 0.0
        self.commands_ma: list[float] = []
        self.corrupt_next: bool | int = False
        self._current_ma = 0.0

    def _state_line(self) -> str:
        t_s = self.t_ms / 1000.0
        dt = self.period_ms / 1000.0
        angle = self.angle(t_s)
        speed = (angle - self.angle(t_s - dt)) / dt
        self.t_ms += self.period_ms
        return (
            f"S {self.t_ms - self.period_ms:.0f} {angle:.6f} {speed:.5f} "
            f"{self._current_ma:.4f} {self.joystick(t_s):.4f}"
        )

    def _reply(self, payload: str) -> str:
        fields = payload.split()
        if payload == "HELLO":
            return f"OK {self.role} {self.firmware}"
        if payload == "Q":
            return self._state_line()
        if payload == "STOP":
            self._current_ma = 0.0
            return "OK STOP"
        if len(fields) == 2 and fields[0] == "I":
            try:
                value = float(fields[1])
            except ValueError:
                return f"E bad current {fields[1]!r}"
            if not math.isfinite(value):
                return f"E bad current {fields[1]!r}"
            self._current_ma = value
            self.commands_ma.append(value)
            return self._state_line()
        return f"E unknown command {payload!r}"

    def _wire(self, line: bytes) -> bytes:
        if self.corrupt_next:  # True, or how many lines in a row
            line = line[:-3] + b"00\n"
            self.corrupt_next = int(self.corrupt_next) - 1
        return line
