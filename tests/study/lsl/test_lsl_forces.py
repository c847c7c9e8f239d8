"""A real follower's forces from an LSL stream (the lab's amplifier, here an outlet in
this process on the suite's loopback-only liblsl configuration): the named channels are
stored, a stream that stops sending ends the trial with one line, and a whole session
on the host-built dial and drive stores every trial as measured."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from study.cli import main
from study.lsl.config import ENV, is_loopback_only, load_pylsl
from study.lsl.forces import LslForces
from study.tasks.lcca.trial import lcca_loop
from teleop_core.loop.follower_units import PhysicalFollower
from teleop_core.loop.hardware import Esp32Unit, HardwareDriver, HardwareError
from teleop_core.loop.host_unit import HostUnit
from teleop_core.loop.layout import SAMPLE_COLUMNS
from tests.firmware_build import host_firmware
from tests.study.conftest import init_study, one_error_line
from tests.study.test_hardware_session import TRIAL_S, _trials, short_trials

# the fixtures, imported for the tests below
__all__ = ["host_firmware", "short_trials"]

PROXIMAL_N, DISTAL_N = 0.42, 0.17
"""What the amplifier's stream sends: channel 2 the proximal force, channel 0 the distal
one (channel 1 is another signal of the amplifier's)."""


class Amplifier:
    """An LSL outlet of three channels at 200 Hz, from a thread; `pause` stops its
    samples (the stream stays)."""

    def __init__(self, name: str) -> None:
        assert is_loopback_only(Path(os.environ[ENV]))  # never liblsl's defaults
        pylsl = load_pylsl()
        info = pylsl.StreamInfo(name, "Force", 3, 200.0, "double64", f"amp-{name}")
        self.outlet = pylsl.StreamOutlet(info)
        self.paused = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._push, daemon=True)

    def _push(self) -> None:
        while not self._stop.is_set():
            if not self.paused.is_set():
                self.outlet.push_sample([DISTAL_N, 9.0, PROXIMAL_N])
            time.sleep(0.005)

    def __enter__(self) -> Amplifier:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        del self.outlet


@pytest.fixture
def amplifier(request: pytest.FixtureRequest) -> Iterator[tuple[str, Amplifier]]:
    name = f"FT-{request.node.name[-20:]}-{os.getpid()}"
    with Amplifier(name) as amp:
        yield name, amp


def test_the_named_channels_are_the_stored_forces_and_a_silent_stream_ends_the_trial(
    host_firmware: Path, amplifier: tuple[str, Amplifier], patient_host: None
) -> None:
    name, amp = amplifier
    with HostUnit(host_firmware, "dial") as dial, HostUnit(host_firmware, "drive") as drive:
        follower = PhysicalFollower.open(
            drive.port, lambda: LslForces(f"name='{name}'", proximal_channel=2, distal_channel=0)
        )
        driver = HardwareDriver(Esp32Unit(dial.port, "dial"), follower=follower)
        loop = lcca_loop("VO", seed=1, estimator=None)
        loop.start(driver)
        kept = loop.advance(0.5)
        assert driver.record()["force_sensor_firmware"] == f"lsl {name}"
        amp.paused.set()
        paused = time.monotonic()
        try:
            with pytest.raises(HardwareError, match=f"no sample from the LSL stream name='{name}'"):
                loop.advance(1.0)
            # noticed after the stale limit (0.1 s from the last sample, which may have
            # come one 200 Hz period before the pause), within a few acquisitions of it
            assert 0.1 - 0.006 <= time.monotonic() - paused < 0.5
        finally:
            driver.close()
    assert len(kept) == 50
    # the sensor is the reference: the true force, beside the estimate from the current
    proximal = kept[:, SAMPLE_COLUMNS.index("reference_force_n")]
    distal = kept[:, SAMPLE_COLUMNS.index("distal_force_n")]
    assert np.all(proximal == PROXIMAL_N)
    assert np.all(distal == DISTAL_N)


def test_a_stream_with_too_few_channels_or_none_is_refused(
    amplifier: tuple[str, Amplifier],
) -> None:
    name, _ = amplifier
    with pytest.raises(HardwareError, match="has 3 channel\\(s\\); expected channels 3 and 0"):
        LslForces(f"name='{name}'", proximal_channel=3, distal_channel=0)
    with pytest.raises(HardwareError, match=r"no LSL stream name=.nobody. found within 0\.3 s"):
        LslForces("name='nobody'", 0, 1, resolve_s=0.3)


def test_a_whole_session_with_forces_from_lsl_is_stored_as_measured(
    tmp_path: Path,
    host_firmware: Path,
    short_trials: None,
    patient_host: None,
    amplifier: tuple[str, Amplifier],
    capsys: pytest.CaptureFixture[str],
) -> None:
    name, _ = amplifier
    design = (
        'name = "lsl forces"\nseed = 5\ntrials_per_condition = 1\npractice_trials = 0\n'
        "[groups]\nnovice = 1\n"
        f'[sensors]\nsource = "lsl"\nstream = "name=\'{name}\'"\n'
        "proximal_channel = 2\ndistal_channel = 0\n"
    )
    db = init_study(tmp_path, design, ("novice",))
    with HostUnit(host_firmware, "dial", hand="0.2") as dial:
        argv = ["run", "--participant", "P001", "--driver", "hardware", "--port", dial.port]
        # a drive port with nothing behind it: one line, no trial
        line = one_error_line(capsys, [*argv, "--drive-port", str(tmp_path / "none"), "--db", db])
        assert f"--drive-port {tmp_path / 'none'}: cannot open serial port" in line
        assert _trials(db) == []
        with HostUnit(host_firmware, "drive") as drive:
            assert main([*argv, "--drive-port", drive.port, "--db", db]) == 0
    trials = _trials(db)
    assert len(trials) == 2
    for t in trials:
        assert t.status == "completed"
        assert t.samples_stored == round(TRIAL_S * 100)  # type: ignore[attr-defined]
        assert t.summary["forces"] == "measured"
        assert t.summary["force_sensor_firmware"] == f"lsl {name}"
        assert t.summary["peak_proximal_reference_force_n"] == pytest.approx(PROXIMAL_N)
