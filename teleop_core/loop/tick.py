"""The loop's 1 kHz tick: master controller, dial, environment, follower drive (`_make`).

Everything that must run at the device rate lives here, in one numba function over flat
arrays, because the headless loop has to run >= 200x faster than real time: a Python
call per tick costs more than the whole budget of 5 us per tick. Between two events
(an acquisition, an estimate, a driver update or a packet arriving) the inputs that
cross the link are held, so `run_ticks` advances many ticks per call; the Python side
(`core.py`) handles the events.

Per tick, in this order ([endovascular], III-B and IV-A):
0. packets due from the link (scheduled by the caller, so that a packet arriving
   between events does not cost a call of its own);
1. master controller at 1 kHz on the dial's 12-bit encoder: tau_h (eq. 7, HV only) from
   the last force received, tau_return (eq. 8), tau_total (eq. 9), i_cmd = Psi (eq. 10);
2. the dial (eq. 6) under that current and the operator's hand;
3. the environment (phantom) at the guidewire's insertion, speed and rotation;
4. the follower drive under the last speed command received and the environment's
   proximal force; the guidewire rotation follows the last joystick rate received;
5. the firmware's current low-pass for the next acquisition; one log row.


The environment is any numba function `env(state, params, insertion_m, speed_m_s,
rotation_rad, dt_s, out)` that writes ENV_OUT values to `out`; `kernel.py` binds one in
and compiles the tick (`kernel_for`). The arrays' layouts are in `layout.py`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from teleop_core._jit import numba_module
from teleop_core.estimation.stream import (
    EST_FINAL,
    ESTIMATE_OUT,
    stream_estimate,
    stream_push,
)
from teleop_core.follower.plant import (
    F_IQ,
    F_OMEGA,
    F_OMEGA_EST,
    F_THETA,
    FOLLOWER_OUT,
    follower_tick,
)
from teleop_core.follower.plant import OMEGA as FS_OMEGA
from teleop_core.follower.plant import THETA as FS_THETA
from teleop_core.loop.layout import (
    E_BRANCH,
    E_DISTAL,
    E_PROXIMAL,
    E_SUCCESS,
    E_TIP_X,
    E_TIP_Y,
    E_TIP_Z,
    ENV_OUT,
    L_BRANCH,
    L_FORCE_EST,
    L_FORCE_RX,
    L_HAND_B,
    L_HAND_K,
    L_HAND_PUSH,
    L_HAND_TARGET,
    L_I_CMD_MA,
    L_IQ_FILT,
    L_N_ACQ,
    L_N_CMD,
    L_N_EST,
    L_NOISE_POS,
    L_OMEGA_FILT,
    L_ROT_ACTION,
    L_ROT_RATE_RX,
    L_ROTATION,
    L_SEND_PENDING,
    L_SPEED_CMD_RX,
    L_SUCCESS,
    L_TAU_H,
    L_TAU_PREV,
    L_TAU_TOTAL,
    L_THETA_Q_PREV,
    L_TICK,
    LOG_BRANCH,
    LOG_CURRENT_CMD,
    LOG_DIAL_ANGLE,
    LOG_DIAL_SPEED,
    LOG_DIAL_TORQUE,
    LOG_DISTAL,
    LOG_FORCE_RX,
    LOG_HAPTIC_TORQUE,
    LOG_IQ,
    LOG_IQ_FILT,
    LOG_OMEGA_EST,
    LOG_PROXIMAL,
    LOG_ROTATION,
    LOG_SPEED_CMD_RX,
    LOG_SUCCESS,
    LOG_T,
    LOG_TIP_X,
    LOG_TIP_Y,
    LOG_TIP_Z,
    LOG_WHEEL_ANGLE,
    LOG_WHEEL_SPEED,
    M_ACQ_EVERY,
    M_BS,
    M_DEADBAND,
    M_DEFER_LAST,
    M_DIAL_EXTERNAL,
    M_DT,
    M_ENC_STEP,
    M_EST_DT,
    M_EST_EVERY,
    M_FAST,
    M_GH,
    M_HAPTICS_ON,
    M_HAS_EST,
    M_IMAX,
    M_IQ_FILTER_S,
    M_KS,
    M_KV,
    M_LEVER,
    M_POLY,
    M_POLY_END,
    M_SAT,
    M_THETA_REF,
    M_VEL_FILTER_S,
    M_WHEEL_R,
    PACKET_FORCE,
    S_BRANCH,
    S_DIAL_ANGLE,
    S_DIAL_TORQUE,
    S_DISTAL,
    S_INSERTION,
    S_PROXIMAL,
    S_PROXIMAL_EST,
    S_ROTATION,
    S_T,
    S_TIP_X,
    S_TIP_Y,
    S_TIP_Z,
    SCH_KIND,
    SCH_TICK,
    SCH_V1,
    SCH_V2,
)
from teleop_core.loop.link import DELIVERED_WIDTH, PK_V1, PK_V2, kernel_deliver, kernel_send
from teleop_core.master.dial import D_OMEGA, D_THETA, dial_tick
from teleop_core.master.haptics import haptic_torque, psi, rate_command, return_torque


def _make(env_fn: Callable[..., None]) -> Callable[..., int]:
    numba = numba_module()

    @numba.njit
    def run_ticks(
        n_ticks: int,
        loop: np.ndarray,
        mp: np.ndarray,
        dial: np.ndarray,
        dp: np.ndarray,
        follower: np.ndarray,
        fp: np.ndarray,
        f_enc_step: float,
        env_state: np.ndarray,
        env_params: np.ndarray,
        log: np.ndarray,
        schedule: np.ndarray,
        est: tuple,
        noise: np.ndarray,
        samples: np.ndarray,
        links: tuple,
    ) -> int:  # pragma: no cover - compiled; exercised through TeleopLoop
        dt = mp[M_DT]
        poly = mp[M_POLY:M_POLY_END]
        lpf_w = mp[M_VEL_FILTER_S] / (mp[M_VEL_FILTER_S] + dt)
        lpf_i = mp[M_IQ_FILTER_S] / (mp[M_IQ_FILTER_S] + dt)
        env_out = np.zeros(ENV_OUT)
        f_out = np.zeros(FOLLOWER_OUT)
        r = mp[M_WHEEL_R]
        next_packet = 0
        n_samples = 0
        fast = mp[M_FAST] != 0.0
        acq_every, est_every = int(mp[M_ACQ_EVERY]), int(mp[M_EST_EVERY])
        est_out = np.zeros(ESTIMATE_OUT)
        packet = np.zeros(DELIVERED_WIDTH)
        q_m, ls_m, lp_m, q_f, ls_f, lp_f, pool, pos = links
        # the estimator's arrays, in `CausalEstimator.kernel_arrays` order
        buf, st, mean, std, mem, pv, w_ih, w_hh, b_ih, b_hh, w_out, b_out, target, ekf_s, ekf_v = (
            est
        )
        # the rate command deferred at the end of the last call (M_DEFER_LAST), now that
        # the driver has acted: what TeleopLoop would otherwise send from Python
        if fast and loop[L_SEND_PENDING] != 0.0:
            loop[L_SEND_PENDING] = 0.0
            speed = rate_command(loop[L_THETA_Q_PREV], mp[M_KV]) / r
            kernel_send(q_f, ls_f, lp_f, pool, pos, loop[L_TICK] * dt, speed, loop[L_ROT_ACTION])
        for k in range(n_ticks):
            # 0'. fast path: packets arriving over the in-kernel link for this tick
            if fast:
                if kernel_deliver(q_m, ls_m, loop[L_TICK], dt, packet):
                    loop[L_FORCE_RX] = packet[PK_V1]
                if kernel_deliver(q_f, ls_f, loop[L_TICK], dt, packet):
                    loop[L_SPEED_CMD_RX] = packet[PK_V1]
                    loop[L_ROT_RATE_RX] = packet[PK_V2]
            # 0. packets that arrive over the link for this tick
            while next_packet < schedule.shape[0] and schedule[next_packet, SCH_TICK] <= k:
                packet = schedule[next_packet]
                if packet[SCH_KIND] == PACKET_FORCE:
                    loop[L_FORCE_RX] = packet[SCH_V1]
                else:
                    loop[L_SPEED_CMD_RX] = packet[SCH_V1]
                    loop[L_ROT_RATE_RX] = packet[SCH_V2]
                next_packet += 1
            # 1. master controller on the dial's quantised angle
            theta_q = math.floor(dial[D_THETA] / mp[M_ENC_STEP]) * mp[M_ENC_STEP]
            w_raw = (theta_q - loop[L_THETA_Q_PREV]) / dt
            loop[L_THETA_Q_PREV] = theta_q
            loop[L_OMEGA_FILT] = lpf_w * loop[L_OMEGA_FILT] + (1.0 - lpf_w) * w_raw
            tau_h = 0.0
            if mp[M_HAPTICS_ON] != 0.0:
                tau_h = haptic_torque(loop[L_FORCE_RX], mp[M_GH], mp[M_DEADBAND], mp[M_SAT])
            tau_ret = return_torque(
                theta_q, loop[L_OMEGA_FILT], mp[M_KS], mp[M_BS], mp[M_THETA_REF]
            )
            # tau_total = tau_haptic + tau_return   (eq. 9)
            tau_total = tau_h + tau_ret
            # i_q,cmd = Psi(tau_total, sgn(d tau_total / dt))   (eq. 10)
            i_cmd, branch = psi(
                tau_total, loop[L_TAU_PREV], loop[L_BRANCH], poly, mp[M_LEVER], mp[M_IMAX]
            )
            loop[L_TAU_PREV] = tau_total
            loop[L_BRANCH] = branch
            loop[L_TAU_H] = tau_h
            loop[L_TAU_TOTAL] = tau_total
            loop[L_I_CMD_MA] = i_cmd
            # 2. the dial under the motor and the hand (eq. 6); a real dial is read instead
            tau_motor = tau_total
            if mp[M_DIAL_EXTERNAL] == 0.0:
                tau_motor = dial_tick(
                    dial,
                    dp,
                    i_cmd,
                    loop[L_HAND_TARGET],
                    loop[L_HAND_K],
                    loop[L_HAND_B],
                    loop[L_HAND_PUSH],
                    dt,
                )
            # 3. the environment at the guidewire
            env_fn(
                env_state,
                env_params,
                follower[FS_THETA] * r,
                follower[FS_OMEGA] * r,
                loop[L_ROTATION],
                dt,
                env_out,
            )
            # 4. the follower drive; the rotary platform follows the joystick rate
            follower_tick(
                follower, fp, f_enc_step, loop[L_SPEED_CMD_RX], env_out[E_PROXIMAL], f_out
            )
            loop[L_ROTATION] += loop[L_ROT_RATE_RX] * dt
            # 5. the firmware's current low-pass (what the next acquisition reads)
            loop[L_IQ_FILT] = lpf_i * loop[L_IQ_FILT] + (1.0 - lpf_i) * f_out[F_IQ]
            loop[L_TICK] += 1.0
            row = log[k]
            row[LOG_T] = loop[L_TICK] * dt
            row[LOG_DIAL_ANGLE] = dial[D_THETA]
            row[LOG_DIAL_SPEED] = dial[D_OMEGA]
            row[LOG_DIAL_TORQUE] = tau_motor
            row[LOG_HAPTIC_TORQUE] = tau_h
            row[LOG_CURRENT_CMD] = i_cmd
            row[LOG_WHEEL_ANGLE] = f_out[F_THETA]
            row[LOG_WHEEL_SPEED] = f_out[F_OMEGA]
            row[LOG_IQ] = f_out[F_IQ]
            row[LOG_IQ_FILT] = loop[L_IQ_FILT]
            row[LOG_OMEGA_EST] = f_out[F_OMEGA_EST]
            row[LOG_PROXIMAL] = env_out[E_PROXIMAL]
            row[LOG_DISTAL] = env_out[E_DISTAL]
            row[LOG_TIP_X] = env_out[E_TIP_X]
            row[LOG_TIP_Y] = env_out[E_TIP_Y]
            row[LOG_TIP_Z] = env_out[E_TIP_Z]
            row[LOG_BRANCH] = env_out[E_BRANCH]
            row[LOG_SUCCESS] = env_out[E_SUCCESS]
            row[LOG_ROTATION] = loop[L_ROTATION]
            row[LOG_FORCE_RX] = loop[L_FORCE_RX]
            row[LOG_SPEED_CMD_RX] = loop[L_SPEED_CMD_RX]
            # 6. fast path: every acquisition happens here, as TeleopLoop._acquire and
            # _send_command do them, with the link's queues and draws in the kernel
            tick = int(loop[L_TICK])
            if fast and tick % acq_every == 0:
                t = tick * dt
                loop[L_N_ACQ] += 1.0
                estimating = tick % est_every == 0
                if mp[M_HAS_EST] != 0.0:
                    iq = row[LOG_IQ_FILT] + noise[int(loop[L_NOISE_POS])]
                    loop[L_NOISE_POS] += 1.0
                    stream_push(st, buf, mean, std, mem, t, iq, row[LOG_OMEGA_EST], 0.0, False)
                    if estimating:
                        ok = stream_estimate(
                            st,
                            buf,
                            pv,
                            w_ih,
                            w_hh,
                            b_ih,
                            b_hh,
                            w_out,
                            b_out,
                            target,
                            ekf_s,
                            ekf_v,
                            mp[M_EST_DT],
                            est_out,
                        )
                        loop[L_FORCE_EST] = est_out[EST_FINAL] if ok else 0.0
                elif estimating:
                    loop[L_FORCE_EST] = row[LOG_PROXIMAL]
                if estimating:
                    loop[L_N_EST] += 1.0
                    kernel_send(q_m, ls_m, lp_m, pool, pos, t, loop[L_FORCE_EST], 0.0)
                out = samples[n_samples]
                out[S_T], out[S_INSERTION] = t, row[LOG_WHEEL_ANGLE] * r
                out[S_ROTATION] = row[LOG_ROTATION]
                out[S_TIP_X], out[S_TIP_Y] = row[LOG_TIP_X], row[LOG_TIP_Y]
                out[S_TIP_Z], out[S_BRANCH] = row[LOG_TIP_Z], row[LOG_BRANCH]
                out[S_PROXIMAL], out[S_PROXIMAL_EST] = row[LOG_PROXIMAL], loop[L_FORCE_EST]
                out[S_DISTAL] = row[LOG_DISTAL]
                out[S_DIAL_ANGLE], out[S_DIAL_TORQUE] = row[LOG_DIAL_ANGLE], row[LOG_DIAL_TORQUE]
                n_samples += 1
                if row[LOG_SUCCESS] != 0.0:
                    loop[L_SUCCESS] = 1.0
                # the master samples the dial: v_gw = k_v theta_m (eq. 5), at the wheel; at
                # a driver tick that ends the call, Python sends it after the driver acts
                if not (k == n_ticks - 1 and mp[M_DEFER_LAST] != 0.0):
                    speed = rate_command(loop[L_THETA_Q_PREV], mp[M_KV]) / r
                    kernel_send(q_f, ls_f, lp_f, pool, pos, t, speed, loop[L_ROT_ACTION])
                else:
                    # sent at the start of the next call, after the driver has acted
                    loop[L_SEND_PENDING] = 1.0
                loop[L_N_CMD] += 1.0
        return n_samples

    return run_ticks
