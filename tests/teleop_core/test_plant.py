"""The simulated drive against closed-form behaviour of eqs. 1-2 and its controllers."""

from __future__ import annotations

import numpy as np
import pytest

from teleop_core.follower.params import FollowerPlantParams
from teleop_core.follower.plant import FollowerDrive
from teleop_core.follower.sensors import quantise


def test_steady_speed_current_is_eq_1_at_constant_speed() -> None:
    plant = FollowerPlantParams().ideal()
    drive = FollowerDrive(plant=plant)
    trace = drive.run(np.full(3000, 6.0), np.full(3000, 1.2))
    iq = trace.iq_a[-1000:].mean()
    # K_t I_q = b w + tau_c + r F at theta_dd = 0
    expected = (
        plant.viscous_damping_n_m_s_per_rad * 6.0
        + plant.coulomb_friction_n_m
        + plant.wheel_radius_m * 1.2
    ) / plant.torque_constant_n_m_per_a
    assert iq == pytest.approx(expected, rel=0.01)
    assert trace.omega_rad_s[-1000:].mean() == pytest.approx(6.0, abs=0.01)


def test_stiction_holds_the_wheel_below_breakaway() -> None:
    plant = FollowerPlantParams()
    drive = FollowerDrive(plant=plant)
    # Speed command 0, a load whose torque stays below the static friction: no motion.
    load = np.full(2000, 0.9 * plant.static_friction_n_m / plant.wheel_radius_m)
    trace = drive.run(np.zeros(2000), load)
    assert np.all(trace.omega_rad_s == 0.0)


def test_voltage_limit_caps_the_current_by_the_back_emf() -> None:
    """At 30 rad/s with 1.5 N the drive needs more current than (V - e) / R allows."""
    plant = FollowerPlantParams()
    trace = FollowerDrive(plant=plant).run(np.full(4000, 30.0), np.full(4000, 1.5))
    omega = trace.omega_rad_s[-500:].mean()
    back_emf = (2 / 3) * plant.torque_constant_n_m_per_a * omega
    assert omega < 29.0  # the speed sags
    assert trace.iq_a[-500:].mean() == pytest.approx(
        (plant.voltage_limit_v - back_emf) / plant.phase_resistance_ohm, rel=0.01
    )


def test_one_tick_at_a_time_equals_a_whole_run() -> None:
    rng = np.random.default_rng(2)
    cmd, load = rng.uniform(-5, 8, 500), rng.uniform(0, 1.5, 500)
    whole = FollowerDrive().run(cmd, load)
    stepwise = FollowerDrive()
    omega = [stepwise.step(c, f)[1] for c, f in zip(cmd, load, strict=True)]
    np.testing.assert_array_equal(omega, whole.omega_rad_s)


def test_as5600_quantisation() -> None:
    step = 2 * np.pi / 4096
    assert quantise(np.array([0.4 * step, 1.0 * step, 2.7 * step]), 4096).tolist() == [
        0.0,
        step,
        2 * step,
    ]
