"""The NOTES transfer functions against their closed-form limits, a direct solve of the
Fig. 8 equations, and a time-domain simulation of the same model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from teleop_core.notes.params import DOFS, MsdParams, default_params
from teleop_core.notes.simulate import simulate_response
from teleop_core.notes.transfer import (
    force_bandwidth_hz,
    force_tf,
    frequency_response,
    settling_time_s,
    velocity_tf,
)

P = MsdParams(m_m=0.3, m_s=0.6, k_s=1970.0, b_m=15.0, b_s=3.6)


def _solve(p: MsdParams, s: complex) -> tuple[complex, complex]:
    """V and F at s from the Laplace-domain equations of Fig. 8 solved numerically."""
    open_end = np.array(
        [
            [p.m_m * s**2 + (p.b_m + p.b_s) * s + p.k_s, -(p.b_s * s + p.k_s)],
            [-(p.b_s * s + p.k_s), p.m_s * s**2 + p.b_s * s + p.k_s],
        ]
    )
    _, x_s = np.linalg.solve(open_end, [1.0, 0.0])
    x_m = 1.0 / (p.m_m * s**2 + (p.b_m + p.b_s) * s + p.k_s)  # clamped: x_s = 0
    return s * x_s, (p.b_s * s + p.k_s) * x_m


@pytest.mark.parametrize("f_hz", [0.3, 3.0, 17.0, 80.0])
def test_v_and_f_match_a_direct_solve_of_the_mechanics(f_hz: float) -> None:
    s = 2j * np.pi * f_hz
    v, f = _solve(P, s)
    assert frequency_response(P, "V", np.array([f_hz]))[0] == pytest.approx(v, rel=1e-9)
    assert frequency_response(P, "F", np.array([f_hz]))[0] == pytest.approx(f, rel=1e-9)
    z = frequency_response(P, "Z", np.array([f_hz]))[0]
    assert z == pytest.approx(f / v, rel=1e-9)


def test_closed_form_limits() -> None:
    lo, hi = np.array([1e-7]), np.array([1e5])
    # F(0) = 1 (no integrator), V(0) = 1 / b_m, Z(0) = b_m
    assert frequency_response(P, "F", lo)[0] == pytest.approx(1.0, rel=1e-6)
    assert frequency_response(P, "V", lo)[0] == pytest.approx(1 / P.b_m, rel=1e-6)
    assert frequency_response(P, "Z", lo)[0] == pytest.approx(P.b_m, rel=1e-6)
    # high frequency: F ~ b_s / (M_m s), Z ~ M_s s
    s = 2j * np.pi * hi[0]
    assert frequency_response(P, "F", hi)[0] == pytest.approx(P.b_s / (P.m_m * s), rel=1e-3)
    assert frequency_response(P, "Z", hi)[0] == pytest.approx(P.m_s * s, rel=1e-3)


def test_the_printed_f_has_an_integrator_ours_does_not() -> None:
    # paper eq. 4: k_s / (s * (M_m M_s s^3 + ...)), unbounded as s -> 0
    m_m, m_s, k_s, b_m, b_s = P.as_tuple()
    printed = (
        [k_s],
        [
            m_m * m_s,
            m_s * (b_s + b_m) + m_m * b_s,
            (m_s + m_m) * k_s + 2 * b_m * b_s,
            b_m * k_s,
            0.0,
        ],
    )
    w = 2 * np.pi * np.array([1e-3, 1e-2])
    _, h = signal.freqs(*printed, worN=w)
    assert abs(h[0]) / abs(h[1]) == pytest.approx(10.0, rel=1e-2)
    assert abs(frequency_response(P, "F", np.array([1e-3]))[0]) == pytest.approx(1.0, rel=1e-4)


@pytest.mark.parametrize("boundary", ["clamped", "open"])
def test_time_domain_simulation_matches_the_transfer_function(boundary: str) -> None:
    dof = default_params("translation")
    t = np.arange(0.0, 2.0, 1e-3)
    u = 2.0 * signal.chirp(t, 1.0, 2.0, 20.0)
    y = simulate_response(dof, t, u, boundary, nonlinear=False)
    num, den = force_tf(dof.linear) if boundary == "clamped" else velocity_tf(dof.linear)
    if boundary == "open":
        den = np.append(den, 0.0)  # X_s = V / s
    # the simulation samples mid-hold: compare with lsim of the same held input at t + dt/2
    t_fine = np.arange(0.0, 2.0, 1e-4)
    _, y_ref, _ = signal.lsim((num, den), np.repeat(u, 10), t_fine)
    y_ref = y_ref[5::10]
    assert np.max(np.abs(y - y_ref)) < 0.01 * np.max(np.abs(y_ref))


@pytest.mark.parametrize(("dof", "paper_hz"), [("translation", 18.1), ("rotation", 5.7)])
def test_default_bandwidth_is_the_papers_within_10_percent(dof: str, paper_hz: float) -> None:
    assert force_bandwidth_hz(default_params(dof).linear) == pytest.approx(paper_hz, rel=0.1)


def test_bandwidth_and_settling_of_a_first_order_limit() -> None:
    # b_s = 0, tiny M_m: F ~ k_s / ((b_m) s + k_s), a first-order lag with corner k_s / b_m
    p = MsdParams(m_m=1e-9, m_s=1.0, k_s=100.0, b_m=10.0, b_s=1e-9)
    assert force_bandwidth_hz(p) == pytest.approx(10.0 / (2 * np.pi), rel=1e-3)
    # 2 % settling of 1 - exp(-t / tau): tau ln 50
    assert settling_time_s(p) == pytest.approx(0.1 * np.log(50), abs=2e-4)
    assert set(DOFS) == {"translation", "rotation"}
