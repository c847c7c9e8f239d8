"""Eq. 1 and its least-squares fit."""

from __future__ import annotations

import numpy as np
import pytest

from teleop_core.follower.params import FollowerPlantParams, FollowerSensorParams
from teleop_core.follower.physics import PhysicsParams, fit_physics
from teleop_core.follower.recording import FollowerRecording

from .conftest import simulate_recording

TRUE = PhysicsParams(
    torque_constant_n_m_per_a=0.05,
    inertia_kg_m2=8e-6,
    viscous_damping_n_m_s_per_rad=4e-5,
    coulomb_friction_n_m=1.5e-3,
    wheel_radius_m=0.012,
    offset_n=0.07,
    sign_speed_rad_s=0.3,
)


def test_force_is_eq_1_solved_for_f() -> None:
    # K_t I_q = J a + b w + tau_c sgn(w) + r F  ->  F by hand at w >> w_s (tanh = 1):
    iq, w, a = 0.4, 6.0, 120.0
    by_hand = (0.05 * 0.4 - 8e-6 * 120.0 - 4e-5 * 6.0 - 1.5e-3) / 0.012 + 0.07
    assert TRUE.force(np.array([iq]), np.array([w]), np.array([a]))[0] == pytest.approx(
        by_hand, rel=1e-6
    )


def test_fit_recovers_the_parameters_that_generated_the_data() -> None:
    rng = np.random.default_rng(4)
    n = 8000
    t = np.arange(n) * 0.01
    omega = 8 * np.sin(2 * np.pi * 0.13 * t) + 3 * np.sin(2 * np.pi * 0.71 * t)
    alpha = np.gradient(omega, t)
    iq = 0.3 + 0.2 * np.sin(2 * np.pi * 0.05 * t) + rng.normal(0, 0.05, n)
    f_ref = TRUE.force(iq, omega, alpha) + rng.normal(0, 0.005, n)
    rec = FollowerRecording.from_arrays(t, iq, np.cumsum(omega) * 0.01, omega, f_ref, alpha=alpha)
    fit = fit_physics(rec, wheel_radius_m=0.012, sign_speed_rad_s=0.3)
    assert fit.torque_constant_n_m_per_a == pytest.approx(0.05, rel=0.005)
    assert fit.inertia_kg_m2 == pytest.approx(8e-6, rel=0.05)
    assert fit.viscous_damping_n_m_s_per_rad == pytest.approx(4e-5, rel=0.05)
    assert fit.coulomb_friction_n_m == pytest.approx(1.5e-3, rel=0.05)
    assert fit.offset_n == pytest.approx(0.07, abs=0.005)


def test_fit_on_the_simulated_drive_recovers_its_torque_constant_and_friction() -> None:
    """The ideal drive (eqs. 1-2 only) through a clean sensor chain."""
    plant = FollowerPlantParams().ideal()
    sensors = FollowerSensorParams(
        current_filter_s=0.0, current_noise_a=0.002, force_sensor_noise_n=0.002
    )
    rec = simulate_recording(120.0, seed=5, plant=plant, sensors=sensors)
    fit = fit_physics(rec, wheel_radius_m=plant.wheel_radius_m)
    assert fit.torque_constant_n_m_per_a == pytest.approx(plant.torque_constant_n_m_per_a, rel=0.02)
    assert fit.coulomb_friction_n_m == pytest.approx(plant.coulomb_friction_n_m, rel=0.2)
    residual = rec.f_ref - fit.force(rec.iq, rec.omega, rec.alpha)
    # What remains is sensor noise, mostly theta_dd differentiated from a 12-bit angle.
    assert np.sqrt(np.mean(residual**2)) < 0.05


def test_fit_respects_physical_signs() -> None:
    """Friction and inertia cannot come out negative, whatever the data."""
    rng = np.random.default_rng(0)
    t = np.arange(500) * 0.01
    omega = rng.normal(0, 3, 500)
    rec = FollowerRecording.from_arrays(t, rng.normal(0, 0.1, 500), t, omega, rng.normal(0, 1, 500))
    fit = fit_physics(rec)
    assert fit.inertia_kg_m2 >= 0
    assert fit.viscous_damping_n_m_s_per_rad >= 0
    assert fit.coulomb_friction_n_m >= 0
    assert fit.torque_constant_n_m_per_a > 0
