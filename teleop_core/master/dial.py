"""The simulated dial: its PMSM's current response and output hysteresis, and eq. 6.

- Actuator: the ESP32's closed current loop as a first-order lag towards the commanded
  current (fast: what the hand feels has no 8 Hz lag; the bench's gauge has, see
  `gauge_force`); the output force on the calibration lever moves between the loading and
  unloading polynomials (eqs. 14-15) after each reversal of the current's magnitude,
  over `hysteresis_width_ma` (a Dahl-type transition), so a calibration of the
  simulated dial finds the paper's loop; the torque is that force times the lever arm.
- Mechanics (eq. 6): J_m theta_dd + B_m theta_d + tau_friction = tau_motor + tau_hand,
  with static (breakaway) and Coulomb friction, where tau_motor is the actuator torque
  that renders eq. 9 and tau_hand is the operator's hand (a stiffness and damping
  around the angle the hand aims for, plus a push): eq. 6's "tau_motor + tau_haptic"
  split into the motor's rendered torque and the person's.

The kernels are numba functions on flat float64 arrays so that the closed loop can call
them at 10 kHz inside its compiled tick; the layout constants below name the slots.
"""

from __future__ import annotations

import math

import numpy as np

from teleop_core._jit import njit
from teleop_core._typing import Float1D
from teleop_core.follower.sensors import lowpass
from teleop_core.master.params import DialParams

# Dial state layout
D_THETA, D_OMEGA, D_I_MA, D_HYST, D_I_ABS_PREV = range(5)
DIAL_STATE_SIZE = 5
# Dial parameter layout
(
    P_J,
    P_B,
    P_TS,
    P_TC,
    P_TAU_I,
    P_HW,
    P_LEVER,
    P_LA,
    P_LB,
    P_LC,
    P_UA,
    P_UB,
    P_UC,
) = range(13)
SUBSTEPS = 10
"""Integration substeps per 1 kHz device tick (the dial's hand-coupled mode is fast)."""


def dial_param_vector(params: DialParams) -> Float1D:
    p = params.polynomials
    return np.array(
        [
            params.inertia_kg_m2,
            params.viscous_damping_n_m_s_per_rad,
            params.static_friction_n_m,
            params.coulomb_friction_n_m,
            params.current_time_constant_s,
            params.hysteresis_width_ma,
            p.lever_arm_m,
            *p.loading,
            *p.unloading,
        ],
        dtype=np.float64,
    )


@njit(cache=True)
def actuator_torque(state: np.ndarray, p: np.ndarray, i_cmd_ma: float, gain: float) -> float:
    """Advance the current and the hysteresis by one step of dt; return the motor torque,
    N m. `gain` = 1 - exp(-dt / tau_i) (`current_gain`)."""
    # first-order closed current loop: i += (i_cmd - i)(1 - e^(-dt/tau))
    state[D_I_MA] += (i_cmd_ma - state[D_I_MA]) * gain
    i_abs = abs(state[D_I_MA])
    # Dahl-type move towards the loading (s = 1) or unloading (s = 0) branch
    d = i_abs - state[D_I_ABS_PREV]
    state[D_I_ABS_PREV] = i_abs
    if d > 0.0:
        state[D_HYST] += (1.0 - state[D_HYST]) * min(d / p[P_HW], 1.0)
    elif d < 0.0:
        state[D_HYST] -= state[D_HYST] * min(-d / p[P_HW], 1.0)
    f_load = (p[P_LA] * i_abs + p[P_LB]) * i_abs + p[P_LC]
    f_unload = (p[P_UA] * i_abs + p[P_UB]) * i_abs + p[P_UC]
    force = f_unload + state[D_HYST] * (f_load - f_unload)
    # the fits' intercepts are not physics: no current, no force
    force = max(force, 0.0) * min(i_abs / 0.05, 1.0)
    tau = p[P_LEVER] * force
    return tau if state[D_I_MA] >= 0.0 else -tau


@njit(cache=True)
def current_gain(p: np.ndarray, dt: float) -> float:
    return 1.0 - math.exp(-dt / p[P_TAU_I])


@njit(cache=True)
def dial_tick(
    state: np.ndarray,
    p: np.ndarray,
    i_cmd_ma: float,
    hand_target_rad: float,
    hand_stiffness_n_m_per_rad: float,
    hand_damping_n_m_s_per_rad: float,
    hand_torque_n_m: float,
    dt: float,
) -> float:
    """One device tick of eq. 6 in SUBSTEPS; returns the mean motor torque, N m."""
    dte = dt / SUBSTEPS
    J, B, ts, tc = p[P_J], p[P_B], p[P_TS], p[P_TC]
    gain = current_gain(p, dte)
    dte_j = dte / J  # once per tick: a division would sit on every substep's chain
    tau_sum = 0.0
    for _ in range(SUBSTEPS):
        tau_motor = actuator_torque(state, p, i_cmd_ma, gain)
        tau_sum += tau_motor
        omega = state[D_OMEGA]
        tau_hand = (
            hand_stiffness_n_m_per_rad * (hand_target_rad - state[D_THETA])
            - hand_damping_n_m_s_per_rad * omega
            + hand_torque_n_m
        )
        tau = tau_motor + tau_hand
        if omega == 0.0:
            if abs(tau) <= ts:
                continue  # static friction holds the dial
            tau_f = ts if tau > 0.0 else -ts
        else:
            tau_f = tc if omega > 0.0 else -tc
        # J_m theta_dd + B_m theta_d + tau_friction = tau_motor + tau_hand   (eq. 6)
        omega_new = omega + (tau - B * omega - tau_f) * dte_j
        if omega != 0.0 and omega_new * omega < 0.0:
            omega_new = 0.0  # friction stops the dial; it cannot reverse it
        state[D_OMEGA] = omega_new
        state[D_THETA] += omega_new * dte
    return tau_sum / SUBSTEPS


@njit(cache=True)
def _clamped_run(state: np.ndarray, p: np.ndarray, i_cmd_ma: np.ndarray, dt: float) -> np.ndarray:
    out = np.empty(i_cmd_ma.shape[0])
    gain = current_gain(p, dt / SUBSTEPS)
    for k in range(i_cmd_ma.shape[0]):
        tau = 0.0
        for _ in range(SUBSTEPS):
            tau = actuator_torque(state, p, i_cmd_ma[k], gain)
        out[k] = tau
    return out


def clamped_torque(params: DialParams, current_cmd_a: Float1D, dt_s: float) -> Float1D:
    """Motor torque (N m) with the dial held against the gauge, one value per command
    sample (held over dt_s); the state starts at rest."""
    state = np.zeros(DIAL_STATE_SIZE)
    cmd_ma = np.ascontiguousarray(current_cmd_a, dtype=np.float64) * 1000.0  # A -> mA
    return _clamped_run(state, dial_param_vector(params), cmd_ma, dt_s)


def gauge_force(
    params: DialParams, current_cmd_a: Float1D, dt_s: float, rng: np.random.Generator
) -> Float1D:
    """What the calibration bench's force gauge reads (N), one value per command sample:
    the lever force, through the lever-and-gauge low-pass, plus gauge noise."""
    force = clamped_torque(params, current_cmd_a, dt_s) / params.polynomials.lever_arm_m
    force = lowpass(force, params.gauge_time_constant_s, dt_s)
    return force + rng.normal(0.0, params.gauge_noise_n, len(force))
