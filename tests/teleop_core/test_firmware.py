"""The units' firmware, built on the host, in the loop with the host's protocol side.

The firmware's own tests (C++, `firmware/host/test`) run from here, so CI builds and runs
them; then the host build runs as a process behind a pseudo-terminal and the host's
side (`teleop_core.loop.hardware`) meets it as it would meet an ESP32: malformed
lines, a unit that stops answering, one unplugged, a garbled line on the wire.
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import serial

from teleop_core.loop.core import TeleopLoop
from teleop_core.loop.environments import tube_with_wall
from teleop_core.loop.hardware import (
    TIMEOUT_S,
    UPDATE_PERIOD_S,
    Esp32Unit,
    HardwareDriver,
    HardwareError,
    UnitGone,
    UnitSilent,
    UnitState,
    encode,
)
from teleop_core.loop.host_unit import HostUnit
from tests.firmware_build import host_firmware

__all__ = ["host_firmware"]  # the fixture, imported for the tests below

COUNT_RAD = 2 * np.pi / 4096


def test_the_firmwares_own_tests_pass(host_firmware: Path) -> None:
    done = subprocess.run(
        [str(host_firmware / "haptic_unit_tests")], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stdout
    assert done.stdout.strip().endswith("tests, 0 failed")
    assert "FAIL" not in done.stdout


def test_the_loop_renders_psi_on_the_host_built_dial(host_firmware: Path) -> None:
    # the simulated hand aims the dial at 0.4 rad over the first second
    with HostUnit(host_firmware, "dial", hand="0:0,1:0.4", joystick="0.5") as unit:
        driver = HardwareDriver.open(unit.port)
        assert driver.unit.firmware == "1.1.0-host"
        result = TeleopLoop(environment=tube_with_wall()).run(1.5, driver)
        record = driver.record()
        driver.close()
    frame = result.to_frame()
    angle = frame["dial_angle_rad"].to_numpy()
    # the AS5600's whole counts
    assert np.allclose(angle / COUNT_RAD, np.round(angle / COUNT_RAD), atol=1e-3)
    # the hand's grip (0.3 N m/rad) holds the dial near its aim; the return spring,
    # rendered through the dial's motor, pulls it back by the torque / grip
    assert 0.25 < angle[-1] < 0.4
    assert frame["insertion_m"].iloc[-1] > 0.005
    # the joystick at half of pi/2 rad/s, from the first state line on
    assert frame["rotation_rad"].iloc[-1] == pytest.approx(0.5 * np.pi / 2 * 1.49, rel=0.03)
    assert record == {"dial_firmware": "1.1.0-host", "dial_corrupt_lines": 0}


def _raw(port: str, line: bytes) -> bytes:
    with serial.Serial(port, 115200, timeout=0.5) as s:
        s.write(line)
        return s.readline()


@pytest.mark.parametrize(
    "line, answer",
    [
        (b"I 1*59\n", b"E checksum mismatch: 'I 1*59'"),
        (b"I 1\n", b"E line without a checksum *HH: 'I 1'"),
        (encode("I abc"), b"E bad current: 'abc'"),
        (encode("W 2"), b"E W is a drive's command; this unit is a dial"),
        (encode("JUMP"), b"E unknown command: 'JUMP'"),
        (b"x" * 300 + b"\n", b"E line too long"),
        (b"\xff\xfe*00\n", b"E non-ASCII byte in the line"),
    ],
)
def test_the_firmware_answers_a_malformed_line_with_e(
    host_firmware: Path, line: bytes, answer: bytes
) -> None:
    with HostUnit(host_firmware, "dial") as unit:
        reply = _raw(unit.port, line)
        assert reply.startswith(answer + b"*")
        # and the host's side reads it as a refusal, then carries on
        esp = Esp32Unit(unit.port, "dial")
        assert isinstance(esp.query(), UnitState)
        esp.close()


def test_the_watchdog_zeroes_the_command_when_the_host_stops_talking(
    host_firmware: Path,
) -> None:
    with HostUnit(host_firmware, "drive") as unit:
        esp = Esp32Unit(unit.port, "drive")
        for _ in range(100):  # 1 s at 100 Hz: the drive speeds up to 5 rad/s
            state = esp.set_speed(5.0)
            time.sleep(UPDATE_PERIOD_S)
        assert state.speed_rad_s == pytest.approx(5.0, abs=1.0)
        time.sleep(0.5)  # silence: the firmware's watchdog (100 ms) zeroes the speed
        assert abs(esp.query().speed_rad_s) < 0.5
        esp.close()


def test_a_frozen_unit_is_noticed_within_three_update_periods(host_firmware: Path) -> None:
    sent: list[float] = []
    answered: list[float] = []

    class Timed(HardwareDriver):
        def exchange(self, current_cmd_a: float) -> UnitState:
            sent.append(time.monotonic())
            state = super().exchange(current_cmd_a)
            answered.append(time.monotonic())
            if len(answered) == 30:
                unit.freeze()  # the unit hangs after its 30th answer
            return state

    with HostUnit(host_firmware, "dial", hand="0.2") as unit:
        driver = Timed(Esp32Unit(unit.port, "dial"))
        with pytest.raises(UnitSilent, match=r"no answer .* within 20 ms"):
            TeleopLoop(environment=tube_with_wall()).run(3.0, driver)
        noticed = time.monotonic()
        unit.thaw()
        driver.close()
    # the command it left unanswered: noticed after the timeout, two update periods
    # (and what a machine shared by many processes adds to a wake-up)
    assert (len(sent), len(answered)) == (31, 30)
    assert TIMEOUT_S <= noticed - sent[-1] < TIMEOUT_S + 0.010
    # after its last answer: the wait for the next update and the timeout, three
    # periods (and what the loop's own ticks take on a loaded machine)
    assert TIMEOUT_S + UPDATE_PERIOD_S <= 3 * UPDATE_PERIOD_S
    assert noticed - answered[-1] < 3 * UPDATE_PERIOD_S + 0.015


def test_a_garbled_line_is_dropped_and_its_command_sent_again(host_firmware: Path) -> None:
    # every 7th state line's angle overwritten with 9s on the wire, its checksum kept
    with HostUnit(host_firmware, "dial", hand="0:0,1:0.4", corrupt_every=7) as unit:
        driver = HardwareDriver.open(unit.port)
        result = TeleopLoop(environment=tube_with_wall()).run(1.0, driver)
        corrupt = driver.unit.corrupt_lines
        driver.close()
    angle = result.to_frame()["dial_angle_rad"].to_numpy()
    # 100 updates and their retries: one line in 7 garbled, none of them used
    assert corrupt >= 12
    assert angle.max() < 0.5  # a 9.99... angle never reached the loop
    assert result.counters.driver_updates == 100


def test_an_unplugged_unit_is_one_error_naming_the_port(host_firmware: Path) -> None:
    with HostUnit(host_firmware, "dial") as unit:
        esp = Esp32Unit(unit.port, "dial")
        esp.query()
        unit.unplug()
        with pytest.raises(UnitGone, match=f"the unit on {unit.port} is gone"):
            esp.query()
        esp.close()  # closing a gone port is quiet


def test_a_port_with_no_one_behind_it_fails_the_greeting(tmp_path: Path) -> None:
    import os
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        start = time.monotonic()
        with pytest.raises(HardwareError, match=r"no greeting from the unit on .* within 0\.3 s"):
            Esp32Unit(os.ttyname(slave), "dial", greeting_s=0.3)
        assert time.monotonic() - start < 0.6
    finally:
        os.close(master)
        os.close(slave)
