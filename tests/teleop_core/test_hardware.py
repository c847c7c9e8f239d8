"""The hardware driver against an emulated ESP32 dial unit on a pseudo-terminal."""

from __future__ import annotations

import numpy as np
import pytest

from teleop_core.loop.core import TeleopLoop
from teleop_core.loop.drivers import OperatorView
from teleop_core.loop.emulator import EmulatedDialUnit
from teleop_core.loop.environments import tube_with_wall
from teleop_core.loop.hardware import (
    Esp32Unit,
    HardwareDriver,
    HardwareError,
    UnitState,
    checksum,
    decode,
    encode,
)


def test_checksum_is_the_xor_of_the_payload() -> None:
    # "I 1" = 0x49 ^ 0x20 ^ 0x31 = 0x58, by hand
    assert checksum("I 1") == "58"
    assert encode("I 1") == b"I 1*58\n"
    assert decode(b"I 1*58\n") == "I 1"


@pytest.mark.parametrize(
    "line, message",
    [(b"I 1*59\n", "checksum mismatch"), (b"I 1\n", "without a checksum"), (b"\xff*00\n", "ASCII")],
)
def test_corrupt_lines_are_refused(line: bytes, message: str) -> None:
    with pytest.raises(HardwareError, match=message):
        decode(line)


def test_state_lines_are_parsed_and_checked() -> None:
    state = UnitState.parse("S 120 0.5 1.25 2.0 -0.5")
    assert (state.t_ms, state.angle_rad, state.joystick) == (120.0, 0.5, -0.5)
    with pytest.raises(HardwareError, match="non-finite"):
        UnitState.parse("S 1 nan 0 0 0")
    assert state.button is False  # a line without the field (firmware before 1.1.0)


def test_the_state_line_s_button_field_is_read_and_checked() -> None:
    assert UnitState.parse("S 120 0.5 1.25 2.0 -0.5 1").button is True
    assert UnitState.parse("S 120 0.5 1.25 2.0 -0.5 0").button is False
    for bad in ("2", "1.0", "x", "-1"):
        with pytest.raises(HardwareError, match=f"button field '{bad}'"):
            UnitState.parse(f"S 120 0.5 1.25 2.0 -0.5 {bad}")
    with pytest.raises(HardwareError, match="expected a state line"):
        UnitState.parse("S 120 0.5 1.25 2.0 -0.5 1 0")  # a field too many


def _view() -> OperatorView:
    return OperatorView(0.0, 0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), "", False)


def _acts(driver: HardwareDriver, buttons: list[bool]) -> list[bool]:
    """Whether each driver update ends the trial, the unit's button as given."""
    done = []
    for button in buttons:
        driver.last = UnitState(0.0, 0.0, 0.0, 0.0, 0.0, button)
        done.append(driver.act(_view()).done)
    return done


class _Follower:
    """Stands in for the real drive: the driver only asks whether there is one."""

    def record(self) -> dict[str, str]:
        return {}


def test_a_press_of_the_dial_s_button_ends_a_physical_phantom_trial() -> None:
    driver = HardwareDriver(unit=None, follower=_Follower())  # type: ignore[arg-type]
    # up, up, down: the press ends the trial at the third update, and it stays ended
    assert _acts(driver, [False, False, True, False]) == [False, False, True, True]
    assert driver.end == "button"


def test_a_button_held_from_the_trial_s_start_is_no_press() -> None:
    driver = HardwareDriver(unit=None, follower=_Follower())  # type: ignore[arg-type]
    assert _acts(driver, [True, True, False, True]) == [False, False, False, True]


def test_the_button_is_ignored_with_a_simulated_phantom() -> None:
    driver = HardwareDriver(unit=None)  # type: ignore[arg-type]
    driver.reach()
    assert _acts(driver, [False, True, False, True]) == [False] * 4
    assert driver.end is None


def test_the_experimenter_s_reach_ends_a_physical_phantom_trial() -> None:
    driver = HardwareDriver(unit=None, follower=_Follower())  # type: ignore[arg-type]
    assert _acts(driver, [False]) == [False]
    driver.reach()  # from another thread in `study run`
    assert _acts(driver, [False, True]) == [True, True]
    assert driver.end == "experimenter"  # the first to decide names the end


def test_the_loop_reads_the_real_dial_and_renders_psi_on_it() -> None:
    with EmulatedDialUnit(angle=lambda t: 0.4 * min(t, 1.0), joystick=lambda t: 0.5) as unit:
        driver = HardwareDriver.open(unit.port)
        assert driver.unit.firmware == "emu-1"
        loop = TeleopLoop(environment=tube_with_wall(), keep_ticks=True)
        result = loop.run(1.5, driver)
        driver.close()
    frame = result.to_frame()
    ticks = result.ticks_frame()
    # the dial angle the loop used is the unit's
    assert frame["dial_angle_rad"].iloc[-1] == pytest.approx(0.4)
    # the guidewire advanced and rotated (joystick at half of pi/2 rad/s)
    assert frame["insertion_m"].iloc[-1] > 0.005
    assert frame["rotation_rad"].iloc[-1] == pytest.approx(0.5 * np.pi / 2 * 1.49, rel=0.02)
    # one current command per driver update, each the master's Psi output at that tick
    assert len(unit.commands_ma) == result.counters.driver_updates
    at_updates = ticks["current_cmd_ma"].to_numpy()[9::10]
    assert np.allclose(unit.commands_ma, at_updates, atol=1e-4)  # sent with 4 decimals
    assert min(unit.commands_ma) < -0.1  # the return spring pushes back on the hand


def test_a_wrong_unit_is_refused() -> None:
    with (
        EmulatedDialUnit(role="drive") as unit,
        pytest.raises(HardwareError, match="expected 'dial'"),
    ):
        HardwareDriver.open(unit.port)


def test_a_silent_unit_is_noticed_within_the_timeout() -> None:
    with EmulatedDialUnit() as unit:
        esp = Esp32Unit(unit.port, "dial", timeout_s=0.05)
        unit.silent = True
        with pytest.raises(HardwareError, match=r"no answer .* within 50 ms"):
            esp.query()


def test_a_corrupted_reply_is_dropped_and_the_command_sent_again() -> None:
    with EmulatedDialUnit() as unit:
        esp = Esp32Unit(unit.port, "dial")
        unit.corrupt_next = True
        # the garbled reply is never a value: the retry's is
        assert esp.set_current(0.001).iq_ma == pytest.approx(1.0)
        assert esp.corrupt_lines == 1
        assert unit.commands_ma == [1.0, 1.0]  # the command went twice
        unit.corrupt_next = 2
        with pytest.raises(HardwareError, match=r"two corrupt replies in a row.*checksum mismatch"):
            esp.set_current(0.002)
        assert esp.corrupt_lines == 3


def test_a_missing_port_is_one_clear_error() -> None:
    with pytest.raises(HardwareError, match="cannot open serial port /dev/nonexistent"):
        Esp32Unit("/dev/nonexistent", "dial")
