"""The simulated dial: current lag, the calibrated hysteresis loop, eq. 6."""

from __future__ import annotations

import math

import numpy as np
import pytest

from teleop_core.master.dial import (
    D_OMEGA,
    D_THETA,
    DIAL_STATE_SIZE,
    clamped_torque,
    dial_param_vector,
    dial_tick,
)
from teleop_core.master.params import DialParams


def test_clamped_torque_settles_on_the_loading_then_the_unloading_branch() -> None:
    p = DialParams()
    lever = p.polynomials.lever_arm_m
    # rise to 3 mA and hold, then fall to 2 mA and hold (0.3 s each, >> the 15 ms lag)
    cmd = np.concatenate([np.linspace(0, 3e-3, 300), np.full(300, 3e-3), np.full(300, 2e-3)])
    tau = clamped_torque(p, cmd, 1e-3)
    assert tau[599] == pytest.approx(lever * p.polynomials.force_n(3.0, "loading"), rel=1e-4)
    assert tau[-1] == pytest.approx(lever * p.polynomials.force_n(2.0, "unloading"), rel=1e-4)


def test_current_follows_a_first_order_lag() -> None:
    p = DialParams()
    tau_i = p.current_time_constant_s
    cmd = np.full(200, 2e-3)
    torque = clamped_torque(p, cmd, 1e-3)
    # at t = tau the current is 1 - 1/e of the step; the torque follows the loading fit
    k = round(tau_i / 1e-3) - 1
    i_ma = 2.0 * (1 - math.exp(-(k + 1) * 1e-3 / tau_i))
    expected = p.polynomials.lever_arm_m * p.polynomials.force_n(i_ma, "loading")
    assert torque[k] == pytest.approx(expected, rel=0.02)


def _push(torque_n_m: float, seconds: float = 0.1) -> np.ndarray:
    p = DialParams()
    state = np.zeros(DIAL_STATE_SIZE)
    pv = dial_param_vector(p)
    for _ in range(round(seconds / 1e-3)):
        dial_tick(state, pv, 0.0, 0.0, 0.0, 0.0, torque_n_m, 1e-3)
    return state


def test_static_friction_holds_the_dial_below_breakaway() -> None:
    state = _push(0.9 * DialParams().static_friction_n_m)
    assert state[D_THETA] == 0.0
    assert state[D_OMEGA] == 0.0


def test_above_breakaway_the_dial_accelerates_as_eq6_says() -> None:
    p = DialParams()
    push = 10 * p.static_friction_n_m
    state = _push(push, seconds=0.01)
    # J theta_dd = push - tau_c (B theta_dot is negligible over 10 ms)
    accel = (push - p.coulomb_friction_n_m) / p.inertia_kg_m2
    assert state[D_OMEGA] == pytest.approx(accel * 0.01, rel=0.02)
