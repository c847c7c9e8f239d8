"""The follower's and the dial's substeps multiply by reciprocals computed once per
tick (1 / R, 1 / w_s, dt / J) where the loop before divided in every substep (a
division's latency sat on each substep's serial chain). Not the same floats: against
the division form, copied below as the reference (plain Python, as the loop computed
it before), the trajectories must agree within SUBSTEP_TOLERANCE of their scale over
seconds of varied commands, loads and hand inputs, stiction included."""

from __future__ import annotations

import math

import numpy as np

from teleop_core.follower.plant import (
    F_IQ,
    F_OMEGA,
    F_THETA,
    FOLLOWER_OUT,
    IQ,
    IQ_CMD,
    IQ_INT,
    OMEGA,
    P_COG,
    P_COULOMB,
    P_DRAG2,
    P_DT,
    P_ILIM,
    P_INERTIA,
    P_KII,
    P_KIW,
    P_KPI,
    P_KPW,
    P_KSAT,
    P_KT,
    P_L,
    P_NCOG,
    P_NSUB,
    P_R,
    P_RETRACT,
    P_STATIC,
    P_STRIBECK,
    P_TF,
    P_VISCOUS,
    P_VMAX,
    P_WHEEL_R,
    STATE_SIZE,
    THETA,
    THETA_Q_PREV,
    W_FILT,
    W_INT,
    FollowerDrive,
    follower_tick,
)
from teleop_core.master.dial import (
    D_OMEGA,
    D_THETA,
    DIAL_STATE_SIZE,
    P_B,
    P_J,
    P_TC,
    P_TS,
    SUBSTEPS,
    actuator_torque,
    current_gain,
    dial_param_vector,
    dial_tick,
)
from teleop_core.master.params import DialParams

SUBSTEP_TOLERANCE = 1e-11
"""How far (relative to each signal's largest magnitude) the reciprocal form may be from
the division form: each substep rounds an operation or two differently (half an ulp
each), and over thousands of substeps the differences stay near 1e-15 here; a rounding
difference that flipped a stick/slip decision or an encoder count would exceed it."""


def _follower_tick_dividing(state, p, encoder_step_rad, omega_cmd, load_n, out):  # type: ignore[no-untyped-def]
    """`follower_tick` as the loop computed it before: a division in each substep."""
    kt, r, J, b = p[P_KT], p[P_WHEEL_R], p[P_INERTIA], p[P_VISCOUS]
    tc, ts, ws = p[P_COULOMB], p[P_STATIC], p[P_STRIBECK]
    ksat, cog, ncog = p[P_KSAT], p[P_COG], p[P_NCOG]
    R, L, vmax, kpi, kii = p[P_R], p[P_L], p[P_VMAX], p[P_KPI], p[P_KII]
    dt, nsub, kpw, kiw = p[P_DT], p[P_NSUB], p[P_KPW], p[P_KIW]
    tf, ilim, drag2, retract = p[P_TF], p[P_ILIM], p[P_DRAG2], p[P_RETRACT]
    n_sub = int(nsub)
    dte = dt / n_sub
    decay = math.exp(-R * dte / L)
    ke = (2.0 / 3.0) * kt
    lpf = tf / (tf + dt)
    theta_q = math.floor(state[THETA] / encoder_step_rad) * encoder_step_rad
    w_raw = (theta_q - state[THETA_Q_PREV]) / dt
    state[THETA_Q_PREV] = theta_q
    state[W_FILT] = lpf * state[W_FILT] + (1.0 - lpf) * w_raw
    e_w = omega_cmd - state[W_FILT]
    w_int = state[W_INT] + kiw * e_w * dt
    w_int = min(max(w_int, -ilim), ilim)
    state[W_INT] = w_int
    iq_cmd = min(max(kpw * e_w + w_int, -ilim), ilim)
    state[IQ_CMD] = iq_cmd
    iq_sum = 0.0
    for _ in range(n_sub):
        omega = state[OMEGA]
        iq = state[IQ]
        e_i = iq_cmd - iq
        v = kpi * e_i + state[IQ_INT] + ke * omega
        if v > vmax:
            v = vmax
        elif v < -vmax:
            v = -vmax
        else:
            state[IQ_INT] += kii * e_i * dte
        i_ss = (v - ke * omega) / R
        iq = i_ss + (iq - i_ss) * decay
        state[IQ] = iq
        iq_sum += iq
        tau = kt * (1.0 - ksat * iq * iq) * iq - r * load_n
        if cog != 0.0:
            tau -= cog * math.sin(ncog * state[THETA])
        if omega == 0.0:
            breakaway = ts if tau > 0.0 else ts * retract
            if abs(tau) <= breakaway:
                continue
            tau_f = breakaway if tau > 0.0 else -breakaway
        else:
            mag = tc + (ts - tc) * math.exp(-(omega / ws) * (omega / ws))
            tau_f = mag if omega > 0.0 else -mag * retract
            tau_f += drag2 * omega * abs(omega)
        omega_new = omega + dte * (tau - b * omega - tau_f) / J
        if omega != 0.0 and omega_new * omega < 0.0:
            omega_new = 0.0
        state[OMEGA] = omega_new
        state[THETA] += omega_new * dte
    out[F_THETA] = state[THETA]
    out[F_OMEGA] = state[OMEGA]
    out[F_IQ] = iq_sum / n_sub


def _dial_tick_dividing(state, p, i_cmd_ma, target, k, b, push, dt):  # type: ignore[no-untyped-def]
    """`dial_tick` as the loop computed it before: a division in each substep."""
    dte = dt / SUBSTEPS
    J, B, ts, tc = p[P_J], p[P_B], p[P_TS], p[P_TC]
    gain = current_gain(p, dte)
    tau_sum = 0.0
    for _ in range(SUBSTEPS):
        tau_motor = actuator_torque(state, p, i_cmd_ma, gain)
        tau_sum += tau_motor
        omega = state[D_OMEGA]
        tau = tau_motor + k * (target - state[D_THETA]) - b * omega + push
        if omega == 0.0:
            if abs(tau) <= ts:
                continue
            tau_f = ts if tau > 0.0 else -ts
        else:
            tau_f = tc if omega > 0.0 else -tc
        omega_new = omega + dte * (tau - B * omega - tau_f) / J
        if omega != 0.0 and omega_new * omega < 0.0:
            omega_new = 0.0
        state[D_OMEGA] = omega_new
        state[D_THETA] += omega_new * dte
    return tau_sum / SUBSTEPS


def _within(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.max(np.abs(a - b)) <= SUBSTEP_TOLERANCE * np.max(np.abs(b)))


def test_follower_substeps_keep_the_dividing_trajectory() -> None:
    # 3 s: speed commands and loads held for 0.1 s each, both directions (withdrawal
    # friction), loads above breakaway at zero command (stiction and slip)
    rng = np.random.default_rng(4)
    cmd = np.repeat(rng.uniform(-10.0, 10.0, 30), 100)
    cmd[1000:1300] = 0.0
    load = np.repeat(rng.uniform(0.0, 2.0, 30), 100)
    drive = FollowerDrive()
    p, step = drive._p, drive._encoder_step
    new, old = np.zeros(STATE_SIZE), np.zeros(STATE_SIZE)
    out_new, out_old = np.zeros(FOLLOWER_OUT), np.zeros(FOLLOWER_OUT)
    rows_new, rows_old = [], []
    for c, f in zip(cmd, load, strict=True):
        follower_tick(new, p, step, c, f, out_new)
        _follower_tick_dividing(old, p, step, c, f, out_old)
        rows_new.append(out_new[:3].copy())
        rows_old.append(out_old[:3].copy())
    a, b = np.array(rows_new), np.array(rows_old)
    for col in (F_THETA, F_OMEGA, F_IQ):
        assert _within(a[:, col], b[:, col])
    assert np.array_equal(a[:, F_OMEGA] == 0.0, b[:, F_OMEGA] == 0.0)  # stuck alike
    assert np.count_nonzero(b[:, F_OMEGA] == 0.0) > 10  # it did stick
    assert np.ptp(b[:, F_OMEGA]) > 5.0


def test_dial_substeps_keep_the_dividing_trajectory() -> None:
    # 3 s: the motor's current command and the hand's aim, stiffness and push varied
    p = dial_param_vector(DialParams())
    rng = np.random.default_rng(6)
    i_cmd = np.repeat(rng.uniform(-300.0, 300.0, 30), 100)
    aim = np.repeat(rng.uniform(-0.5, 0.5, 30), 100)
    stiff = np.repeat(rng.uniform(0.0, 0.3, 30), 100)
    push = np.repeat(rng.uniform(-0.01, 0.01, 30), 100)
    stiff[2000:2500] = push[2000:2500] = 0.0  # let go: the motor alone, then friction
    new, old = np.zeros(DIAL_STATE_SIZE), np.zeros(DIAL_STATE_SIZE)
    rows_new, rows_old = [], []
    for k in range(3000):
        args = (i_cmd[k], aim[k], stiff[k], 0.002, push[k], 0.001)
        t_new = dial_tick(new, p, *args)
        t_old = _dial_tick_dividing(old, p, *args)
        rows_new.append((new[D_THETA], new[D_OMEGA], t_new))
        rows_old.append((old[D_THETA], old[D_OMEGA], t_old))
    a, b = np.array(rows_new), np.array(rows_old)
    for col in range(3):
        assert _within(a[:, col], b[:, col])
    assert np.array_equal(a[:, 1] == 0.0, b[:, 1] == 0.0)
    assert np.ptp(b[:, 0]) > 0.1  # the dial moved
