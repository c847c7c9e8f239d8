"""The real follower in the loop: the host-built drive unit and an emulated forces unit
beside the host-built dial. The drive gets the follower's speed command, its measured
current and speed are what the estimator is fed, the stored forces are the sensors'."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from study.protocol.default_estimator import load_estimator
from study.tasks.lcca.trial import lcca_loop
from teleop_core.estimation.stream import EST_FINAL
from teleop_core.loop.follower_units import (
    EmulatedForceUnit,
    ForceReading,
    ForceUnit,
    PhysicalFollower,
)
from teleop_core.loop.hardware import CorruptLine, Esp32Unit, HardwareDriver, HardwareError
from teleop_core.loop.host_unit import HostUnit
from teleop_core.loop.layout import SAMPLE_COLUMNS
from tests.firmware_build import host_firmware

__all__ = ["host_firmware"]  # the fixture, imported for the tests below


def proximal(t_s: float) -> float:
    return 0.1 + 0.5 * t_s


def distal(t_s: float) -> float:
    return 0.05 * math.sin(2 * math.pi * t_s) ** 2


def test_a_forces_line_parses_and_a_bad_one_is_corrupt() -> None:
    assert ForceReading.parse("F 120 0.2500 -0.0100") == ForceReading(120.0, 0.25, -0.01)
    for bad in ("F 1 2", "S 1 2 3", "F 1 x 2", "F 1 nan 0", "F 1 51 0", "F 1 0 -50.5"):
        with pytest.raises(CorruptLine):
            ForceReading.parse(bad)


def test_the_emulated_forces_unit_answers_its_clock_and_forces() -> None:
    with EmulatedForceUnit(proximal, distal) as emulated:
        unit = ForceUnit.open(emulated.port)
        assert unit.unit.role == "forces"
        readings = [unit.read() for _ in range(3)]
        unit.close()
    assert [r.t_ms for r in readings] == [0.0, 10.0, 20.0]
    assert readings[2].proximal_n == pytest.approx(0.11, abs=1e-4)  # 0.1 + 0.5 * 0.02
    assert readings[1].distal_n == pytest.approx(distal(0.01), abs=1e-4)


def test_the_unit_check_refuses_a_forces_unit_with_one_line() -> None:
    from teleop_core.loop.unit_check import check_unit

    with EmulatedForceUnit() as forces:
        with pytest.raises(HardwareError, match="is a forces unit \\(firmware emu-1\\)"):
            check_unit(forces.port, seconds=0.1)


def test_a_dial_on_the_drive_port_is_refused(host_firmware: Path) -> None:
    with HostUnit(host_firmware, "dial") as dial, EmulatedForceUnit() as forces:
        with pytest.raises(HardwareError, match="is a 'dial'; expected 'drive'"):
            PhysicalFollower.open(dial.port, forces.port)
        with pytest.raises(HardwareError, match="is a 'forces'; expected 'drive'"):
            PhysicalFollower(Esp32Unit(forces.port, None), ForceUnit.open(forces.port))


def test_the_drive_unit_feeds_the_estimator_and_the_sensors_the_stored_forces(
    patient_host: None,
    host_firmware: Path,
) -> None:
    estimator = load_estimator()
    # the hand turns the dial to 0.3 rad: a speed command the drive follows
    with (
        HostUnit(host_firmware, "dial", hand="0:0,0.3:0.3") as dial,
        HostUnit(host_firmware, "drive") as drive,
        EmulatedForceUnit(proximal, distal) as forces,
    ):
        follower = PhysicalFollower.open(drive.port, forces.port)
        driver = HardwareDriver(Esp32Unit(dial.port, "dial"), follower=follower)
        loop = lcca_loop("HV", seed=3, estimator=estimator)
        result = loop.run(1.5, driver)
        record = driver.record()
        driver.close()
        sent = np.array(forces.sent)
    frame = result.to_frame()
    n = len(frame)
    assert n == 150  # one acquisition per 10 ms
    assert record["drive_state_lines"] == n
    assert record["drive_firmware"] == "1.1.0-host"
    assert record["forces"] == "measured"
    assert record["phantom"] == "physical"
    # the stored forces are the sensors' lines, in order (no simulated force)
    assert np.allclose(frame["reference_force_n"], sent[:n, 1])
    assert np.allclose(frame["distal_force_n"], sent[:n, 2])
    assert np.allclose(sent[:n, 1], [proximal(k * 0.01) for k in range(n)], atol=1e-4)
    # the tip's pose is not measured on a physical phantom
    assert frame[["tip_x_m", "tip_y_m", "tip_z_m"]].isna().all().all()
    inputs = np.array(follower.inputs)
    # the drive followed the dial: v = k_v theta (eq. 5), 0.05 m/s/rad * 0.3 rad on a
    # 10 mm wheel is 1.5 rad/s, reached within the trial
    assert inputs[-20:, 2].mean() == pytest.approx(1.5, rel=0.15)
    assert np.any(np.abs(inputs[:, 1]) > 1e-3)  # a measured current, A
    # the wheel's angle is the insertion: x = r theta, the drive's last angle on a 10 mm
    # wheel (how far it got depends on the host's load: the unit runs on the wall clock)
    last_angle_rad = follower.drive.last_state.angle_rad  # type: ignore[union-attr]
    assert frame["insertion_m"].iloc[-1] == pytest.approx(last_angle_rad * 0.010)
    assert last_angle_rad > 0
    # the estimate is the estimator fed the drive's (t, I_q, speed), every other sample
    stream = estimator.stream()
    expected, held = [], 0.0
    for k, (t, iq, w) in enumerate(inputs, start=1):
        stream.push(t, iq, w)
        if k % 2 == 0:
            out = stream.estimate()
            held = out[EST_FINAL] if out is not None else 0.0
        expected.append(held)
    assert np.allclose(frame["proximal_force_n"], expected)
    assert np.any(np.abs(expected) > 0)
    # a physical phantom tells no success: the trial runs to its limit
    assert not result.success


def test_a_drive_that_stops_answering_ends_the_loop_with_one_error(
    host_firmware: Path, patient_host: None
) -> None:
    with (
        HostUnit(host_firmware, "dial") as dial,
        HostUnit(host_firmware, "drive") as drive,
        EmulatedForceUnit(proximal) as forces,
    ):
        follower = PhysicalFollower.open(drive.port, forces.port)
        driver = HardwareDriver(Esp32Unit(dial.port, "dial"), follower=follower)
        loop = lcca_loop("VO", seed=1, estimator=None)
        loop.start(driver)
        kept = loop.advance(0.3)
        drive.freeze()
        try:
            with pytest.raises(HardwareError, match=f"no answer from the unit on {drive.port}"):
                loop.advance(0.3)
        finally:
            drive.thaw()
            driver.close()
    assert len(kept) == 30
    # without an estimator the reference sensor's force is rendered
    est, reference = (
        SAMPLE_COLUMNS.index("proximal_force_n"),
        SAMPLE_COLUMNS.index("reference_force_n"),
    )
    assert np.allclose(kept[1::2, est], kept[1::2, reference])
    assert kept[-1, reference] == pytest.approx(proximal(0.29), abs=1e-4)
