"""The bench scenarios stay inside what the drive and the paper's benches do."""

from __future__ import annotations

import numpy as np

from teleop_core.follower import scenarios


def test_characterisation_holds_the_wheel_and_loads_within_the_platforms_range() -> None:
    cmd, load = scenarios.characterisation(40.0, np.random.default_rng(0))
    assert len(cmd) == len(load) == 40_000
    assert np.all(cmd == 0.0)
    # mean <= 1.2 N plus amplitude <= 0.8 N; taken up from and released to zero
    assert load.max() <= 2.0
    assert load.min() >= -0.4
    assert load[0] == 0.0
    assert abs(load[9_999]) < 0.01


def test_navigation_load_never_exceeds_what_the_drive_can_push() -> None:
    cmd, load = scenarios.teleoperation(120.0, np.random.default_rng(1), max_load_n=1.2)
    assert load.max() <= 1.2
    assert np.abs(cmd).max() <= 10.0


def test_sinusoidal_load_has_the_asked_frequency() -> None:
    cmd, load = scenarios.sinusoidal_load(2.0, 10.0, mean_n=1.0, amplitude_n=0.5)
    spectrum = np.abs(np.fft.rfft(load[1000:] - load[1000:].mean()))
    freqs = np.fft.rfftfreq(len(load[1000:]), 1e-3)
    assert freqs[np.argmax(spectrum)] == 2.0
    assert np.all(cmd == 0)
