"""The dial's rendering laws against the paper's equations, computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from teleop_core.errors import TeleopInputError
from teleop_core.master.haptics import (
    LOADING,
    UNLOADING,
    InverseMap,
    haptic_torque,
    rate_command,
    return_torque,
)
from teleop_core.master.params import CalibrationPolynomials

LOAD = (-0.023155, 0.725796, -0.019272)  # eq. 14
UNLOAD = (-0.043098, 0.743892, 0.022228)  # eq. 15


def f(poly: tuple[float, float, float], i_ma: float) -> float:
    a, b, c = poly
    return a * i_ma**2 + b * i_ma + c


def test_rate_command_is_eq5_and_clockwise_advances() -> None:
    assert rate_command(0.4, 0.05) == pytest.approx(0.02)
    assert rate_command(-0.4, 0.05) == pytest.approx(-0.02)


def test_haptic_torque_deadband_gain_and_saturation() -> None:
    # inside the deadband: nothing
    assert haptic_torque(0.04, 0.02, 0.05, 0.05) == 0.0
    assert haptic_torque(-0.05, 0.02, 0.05, 0.05) == 0.0
    # beyond it: G_h (|F| - F_db), opposing the advance for a resisting force
    assert haptic_torque(1.05, 0.02, 0.05, 0.05) == pytest.approx(-0.02)
    assert haptic_torque(-1.05, 0.02, 0.05, 0.05) == pytest.approx(0.02)
    # saturation
    assert haptic_torque(10.0, 0.02, 0.05, 0.05) == pytest.approx(-0.05)
    assert haptic_torque(math.nan, 0.02, 0.05, 0.05) == 0.0


def test_return_torque_is_eq8() -> None:
    # -K_s (theta - theta_ref) - B_s theta_dot = -0.03 * 0.3 - 2e-3 * 2
    assert return_torque(0.4, 2.0, 0.03, 2e-3, 0.1) == pytest.approx(-0.009 - 0.004)


def test_psi_inverts_the_loading_polynomial_while_torque_grows() -> None:
    m = InverseMap()
    lever = m.polynomials.lever_arm_m
    for force in (0.5, 1.0, 2.0):
        i_a = m(force * lever)
        assert m.branch == LOADING
        assert f(LOAD, i_a * 1000) == pytest.approx(force, abs=1e-9)


def test_psi_switches_to_unloading_when_torque_falls_and_keeps_it_when_constant() -> None:
    m = InverseMap()
    lever = m.polynomials.lever_arm_m
    m(2.0 * lever)
    i_a = m(1.5 * lever)
    assert m.branch == UNLOADING
    assert f(UNLOAD, i_a * 1000) == pytest.approx(1.5, abs=1e-9)
    m(1.5 * lever)  # d tau/dt = 0: the branch is kept
    assert m.branch == UNLOADING


def test_psi_is_odd_in_torque() -> None:
    pos, neg = InverseMap(), InverseMap()
    for tau in (0.01, 0.03, 0.02):
        assert neg(-tau) == pytest.approx(-pos(tau))
        assert neg.branch == pos.branch


def test_psi_saturates_outside_the_calibrated_range() -> None:
    m = InverseMap()
    max_a = m.polynomials.max_current_ma / 1000
    assert m(10.0) == pytest.approx(max_a)
    assert m(-10.0) == pytest.approx(-max_a)
    # falling towards zero on the unloading branch: below eq. 15's intercept (0.022 N at
    # the gauge) there is nothing to render
    lever = m.polynomials.lever_arm_m
    m(0.5 * lever)
    assert m(0.02 * lever) == 0.0
    assert m.branch == UNLOADING


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=30))
def test_psi_never_returns_nan_or_leaves_the_range(torques: list[float]) -> None:
    m = InverseMap()
    max_a = m.polynomials.max_current_ma / 1000
    for tau in torques:
        i = m(tau)
        assert math.isfinite(i)
        assert abs(i) <= max_a + 1e-15


def test_a_polynomial_that_turns_inside_the_range_is_refused() -> None:
    with pytest.raises(TeleopInputError, match="does not rise"):
        CalibrationPolynomials(unloading=(-0.2, 0.74, 0.02), max_current_ma=4.0)


def test_polynomials_from_the_paper_are_the_defaults() -> None:
    p = CalibrationPolynomials()
    assert p.force_n(3.0, "loading") == pytest.approx(f(LOAD, 3.0))
    assert p.force_n(3.0, "unloading") == pytest.approx(f(UNLOAD, 3.0))
    assert np.allclose(p.loading, LOAD)
    assert np.allclose(p.unloading, UNLOAD)
