"""The EKF: the textbook matrix equations, less noise, and no more than a period of lag."""

from __future__ import annotations

import numpy as np

from teleop_core.estimation.ekf import EkfSettings, ForceEkf, filter_forces
from teleop_core.estimation.metrics import lag_samples
from teleop_core.estimation.training import tune_process_noise
from teleop_core.follower.physics import PhysicsParams

PHYSICS = PhysicsParams()


def _reference_filter(
    settings: EkfSettings, dt: float, y: np.ndarray, omega: np.ndarray
) -> np.ndarray:
    """x = x; P = P + Q; S = P + R; K = P S^-1; x = x + K (y - x); P = (I - K) P."""
    Q = np.diag([settings.q_physics_n2, settings.q_hybrid_n2])
    x = None
    P = None
    out = []
    for yk, w in zip(y, omega, strict=True):
        g = np.array(PHYSICS.force_gradient(w, dt))
        common = g @ np.diag([settings.r_iq_a2, settings.r_omega_rad2_s2]) @ g
        R = np.array(
            [[common + settings.r_physics_model_n2, common], [common, common + settings.r_gru_n2]]
        )
        if x is None:
            x, P = yk.copy(), R.copy()
            out.append(x[1])
            continue
        P = P + Q
        K = P @ np.linalg.inv(P + R)
        x = x + K @ (yk - x)
        P = (np.eye(2) - K) @ P
        out.append(x[1])
    return np.array(out)


def test_update_equals_the_matrix_form_of_the_filter() -> None:
    rng = np.random.default_rng(1)
    settings = EkfSettings(q_physics_n2=2e-3, q_hybrid_n2=5e-3, r_gru_n2=4e-3)
    y = rng.normal(1.0, 0.3, (300, 2))
    omega = rng.normal(0, 2, 300)
    got = filter_forces(settings, PHYSICS, 0.01, y[:, 0], y[:, 1], omega)
    np.testing.assert_allclose(got, _reference_filter(settings, 0.01, y, omega), rtol=0, atol=1e-12)


def test_ekf_lowers_noise_without_more_than_one_pipeline_period_of_lag() -> None:
    rng = np.random.default_rng(5)
    n, rate, pipeline = 6000, 100.0, 50.0
    t = np.arange(n) / rate
    truth = 1.0 + 0.6 * np.sin(2 * np.pi * 0.3 * t) + 0.3 * np.sin(2 * np.pi * 1.1 * t)
    omega = 3 * np.sin(2 * np.pi * 0.2 * t)
    noise = rng.normal(0, 0.08, n)  # current noise seen through eq. 1, shared by both
    f_hybrid = truth + noise
    f_physics = truth + 0.15 * np.sin(2 * np.pi * 0.05 * t) + noise  # biased physics stage
    f_ref = truth + rng.normal(0, 0.01, n)
    base = EkfSettings(r_iq_a2=(0.08 / 4.3) ** 2, r_physics_model_n2=0.15**2 / 2, r_gru_n2=1e-4)
    settings, lag = tune_process_noise(
        PHYSICS, base, 1 / rate, f_physics, f_hybrid, omega, f_ref, max_lag_samples=rate / pipeline
    )
    final = filter_forces(settings, PHYSICS, 1 / rate, f_physics, f_hybrid, omega)
    assert np.std(final - truth) < 0.7 * np.std(f_hybrid - truth)
    assert lag_samples(final, truth) - lag_samples(f_hybrid, truth) <= rate / pipeline
    assert lag <= rate / pipeline


def test_first_update_passes_the_hybrid_estimate_through() -> None:
    ekf = ForceEkf(EkfSettings(), PHYSICS, 0.01)
    assert ekf.update(0.4, 0.55, 0.0) == 0.55
