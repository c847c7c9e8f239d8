"""Where a simulated LCCA trial's CPU time goes, per 1 kHz tick, for one checkout.

Run it with the checkout first on PYTHONPATH (it imports only what every version of
haptic-study since the in-kernel estimator has), so that two versions are profiled by
the same code:

    PYTHONPATH=/path/to/checkout python benchmarks/loop_profile.py --trials 4

Two measurements, both in CPU seconds (`time.process_time`, less sensitive than wall
time to the other jobs on a shared machine):

1. Whole trials (outsiders, HV and VO, the shipped estimator, after a warm-up trial):
   the compiled kernel's share (every call to `TeleopLoop._kernel` timed) and the
   Python side's (driver, events, sample hand-off, frame), per simulated tick.
2. Each stage of the tick alone, called `--calls` times in a compiled loop on the
   arrays of a loop that has run 5 s of an HV trial: master controller (eqs. 7-10),
   dial (eq. 6), phantom, follower drive, the two in-kernel link deliveries, the
   estimator's buffer push, physics + EKF, and physics + GRU window + EKF; the GRU
   window is their difference. Each is weighted by how often the tick runs it (the
   estimator at 50 Hz, the push at 100 Hz) to give ns per tick.

Prints one JSON object; `benchmarks/loop_side_by_side.py` runs it for two checkouts.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np


def _lcca_parts():  # type: ignore[no-untyped-def]
    """lcca_loop, simulated_participant and SimulatedParticipant, from wherever this
    checkout keeps them (the task package, or study.protocol before it): the bench
    compares versions from both sides of that move."""
    try:
        from study.protocol.traits import simulated_participant
        from study.tasks.lcca.simulated_participant import SimulatedParticipant
        from study.tasks.lcca.trial import lcca_loop
    except ModuleNotFoundError:  # a checkout from before the task package
        from study.protocol.lcca_trial import lcca_loop, simulated_participant
        from study.protocol.participants import SimulatedParticipant
    return lcca_loop, simulated_participant, SimulatedParticipant


def _trial_split(trials: int, max_s: float) -> dict[str, float]:
    from study.protocol.default_estimator import load_estimator

    lcca_loop, simulated_participant, SimulatedParticipant = _lcca_parts()
    from teleop_core.phantom.lcca import LccaPhantom

    estimator = load_estimator(None)
    phantom = LccaPhantom()
    kernel_cpu = [0.0]

    def run(seed: int, condition: str) -> tuple[float, int]:
        loop = lcca_loop(condition, seed, estimator, None, phantom)
        inner = loop._kernel

        def timed(*args: object) -> int:
            start = time.process_time()
            m = inner(*args)
            kernel_cpu[0] += time.process_time() - start
            return m

        loop._kernel = timed
        traits = simulated_participant("outsider", seed)
        participant = SimulatedParticipant(traits, phantom, give_up_s=max_s)
        loop.run(max_s, participant)
        return loop.t_s, loop.counters.ticks

    run(0, "HV")  # warm-up: the kernel is loaded or compiled
    kernel_cpu[0] = 0.0
    total_cpu, sim_s, ticks = 0.0, 0.0, 0
    for i in range(trials):
        start = time.process_time()
        s, n = run(i // 2, ("HV", "VO")[i % 2])
        total_cpu += time.process_time() - start
        sim_s += s
        ticks += n
    return {
        "sim_s": sim_s,
        "ticks": ticks,
        "cpu_s": total_cpu,
        "sim_per_cpu_s": sim_s / total_cpu,
        "kernel_ns_per_tick": 1e9 * kernel_cpu[0] / ticks,
        "python_ns_per_tick": 1e9 * (total_cpu - kernel_cpu[0]) / ticks,
    }


def _stage_times(calls: int) -> dict[str, float]:
    from study.protocol.default_estimator import load_estimator

    lcca_loop, simulated_participant, SimulatedParticipant = _lcca_parts()
    from teleop_core._jit import numba_module
    from teleop_core.estimation.ekf import ekf_update
    from teleop_core.estimation.stream import ESTIMATE_OUT, stream_estimate, stream_push
    from teleop_core.follower.physics import force_at
    from teleop_core.follower.plant import FOLLOWER_OUT, follower_tick
    from teleop_core.loop import layout as K
    from teleop_core.loop.link import DELIVERED_WIDTH, kernel_deliver
    from teleop_core.master.dial import dial_tick
    from teleop_core.master.haptics import haptic_torque, psi, return_torque
    from teleop_core.phantom.lcca import LccaPhantom, lcca_phantom

    numba = numba_module()
    phantom = LccaPhantom()
    loop = lcca_loop("HV", 0, load_estimator(None), None, phantom)
    loop.start(SimulatedParticipant(simulated_participant("outsider", 0), phantom))
    loop.advance(5.0)
    mp, lp, dt = loop.mp, loop.loop, loop.dt_s
    poly = np.ascontiguousarray(mp[K.M_POLY : K.M_POLY_END])
    est = loop._stream.kernel_arrays()
    (buf, st, mean, std, mem, pv, w_ih, w_hh, b_ih, b_hh, w_out, b_out, target, ekf_s, ekf_v) = est
    links = loop._links

    @numba.njit
    def master(n, f, mp, poly):  # pragma: no cover - compiled
        acc, tau_prev, branch = 0.0, 0.0, 0.0
        for k in range(n):
            theta = 0.01 * ((k % 200) - 100) / 100.0
            tau_h = haptic_torque(f + 1e-4 * (k % 7), mp[K.M_GH], mp[K.M_DEADBAND], mp[K.M_SAT])
            tau_r = return_torque(theta, 0.1, mp[K.M_KS], mp[K.M_BS], mp[K.M_THETA_REF])
            tau = tau_h + tau_r
            i_cmd, branch = psi(tau, tau_prev, branch, poly, mp[K.M_LEVER], mp[K.M_IMAX])
            tau_prev = tau
            acc += i_cmd
        return acc

    @numba.njit
    def dial(n, state, p, dt):  # pragma: no cover - compiled
        acc = 0.0
        for k in range(n):
            acc += dial_tick(state, p, 5.0 * ((k % 100) - 50) / 50.0, 0.05, 0.2, 0.002, 0.0, dt)
        return acc

    @numba.njit
    def env(n, state, params, x0, dt):  # pragma: no cover - compiled
        out = np.zeros(K.ENV_OUT)
        acc = 0.0
        for k in range(n):
            x = x0 + 0.02 * (k % 1000) / 1000.0
            lcca_phantom(state, params, x, 0.01, 0.3, dt, out)
            acc += out[0]
        return acc

    @numba.njit
    def follower(n, state, p, step):  # pragma: no cover - compiled
        out = np.zeros(FOLLOWER_OUT)
        acc = 0.0
        for k in range(n):
            follower_tick(state, p, step, 1.0 if (k // 500) % 2 == 0 else -1.0, 0.3, out)
            acc += out[0]
        return acc

    @numba.njit
    def link(n, q_m, ls_m, q_f, ls_f, tick0, dt):  # pragma: no cover - compiled
        packet = np.zeros(DELIVERED_WIDTH)
        acc = 0
        for k in range(n):
            acc += kernel_deliver(q_m, ls_m, tick0 + k, dt, packet)
            acc += kernel_deliver(q_f, ls_f, tick0 + k, dt, packet)
        return acc

    @numba.njit
    def push(n, st, buf, mean, std, mem):  # pragma: no cover - compiled
        t0 = st[1]  # the last sample's time: time moves on from call to call
        for k in range(n):
            stream_push(
                st,
                buf,
                mean,
                std,
                mem,
                t0 + 0.01 * (k + 1),
                0.1 + 1e-3 * (k % 9),
                2.0 + 1e-2 * (k % 13),
                0.0,
                False,
            )
        return st[0]

    @numba.njit
    def ekf(n, st, pv, ekf_s, ekf_v, dt):  # pragma: no cover - compiled
        acc = 0.0
        for k in range(n):
            f = force_at(pv, st[4] + 1e-4 * (k % 11), st[5], st[6])
            acc += ekf_update(ekf_s, ekf_v, pv, dt, f, f + 0.01, st[5])
        return acc

    @numba.njit
    def estimate(
        n, st, buf, pv, w_ih, w_hh, b_ih, b_hh, w_out, b_out, target, ekf_s, ekf_v, dt
    ):  # pragma: no cover - compiled
        out = np.zeros(ESTIMATE_OUT)
        acc = 0.0
        for k in range(n):
            buf[k % buf.shape[0], 0] += 1e-6
            stream_estimate(
                st, buf, pv, w_ih, w_hh, b_ih, b_hh, w_out, b_out, target, ekf_s, ekf_v, dt, out
            )
            acc += out[2]
        return acc

    est_dt = loop._est_every * dt
    x0 = float(loop.follower[0] * loop.config.plant.wheel_radius_m)
    q_m, ls_m, _, q_f, ls_f = links[0], links[1], links[2], links[3], links[4]
    jobs = {
        "master": (master, (0.5, mp, poly), 1.0),
        "dial": (dial, (loop.dial.copy(), loop.dp, dt), 1.0),
        "phantom": (env, (loop.environment.state.copy(), loop.environment.params, x0, dt), 1.0),
        "follower": (follower, (loop.follower.copy(), loop.fp, loop.f_enc_step), 1.0),
        "link": (link, (q_m.copy(), ls_m.copy(), q_f.copy(), ls_f.copy(), lp[K.L_TICK], dt), 1.0),
        "buffer_push": (push, (st.copy(), buf.copy(), mean, std, mem), 1.0 / loop._acq_every),
        "physics_ekf": (ekf, (st.copy(), pv, ekf_s.copy(), ekf_v, est_dt), 1.0 / loop._est_every),
        "estimator": (
            estimate,
            (
                st.copy(),
                buf.copy(),
                pv,
                w_ih,
                w_hh,
                b_ih,
                b_hh,
                w_out,
                b_out,
                target,
                ekf_s.copy(),
                ekf_v,
                est_dt,
            ),
            1.0 / loop._est_every,
        ),
    }
    out: dict[str, float] = {}
    for name, (fn, args, per_tick) in jobs.items():
        n = calls if per_tick == 1.0 else max(calls // 20, 1000)
        fn(1, *args)  # compile
        best = np.inf
        for _ in range(3):
            start = time.process_time()
            fn(n, *args)
            best = min(best, (time.process_time() - start) / n)
        out[f"{name}_ns_per_call"] = 1e9 * best
        out[f"{name}_ns_per_tick"] = 1e9 * best * per_tick
    out["gru_window_ns_per_call"] = out["estimator_ns_per_call"] - out["physics_ekf_ns_per_call"]
    out["gru_window_ns_per_tick"] = out["estimator_ns_per_tick"] - out["physics_ekf_ns_per_tick"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--trials", type=int, default=4)
    parser.add_argument("--max-s", type=float, default=60.0)
    parser.add_argument("--calls", type=int, default=200_000)
    args = parser.parse_args()
    result = {"checkout": os.environ.get("PYTHONPATH", ""), "data": "simulated"}
    result["trials"] = _trial_split(args.trials, args.max_s)
    result["stages"] = _stage_times(args.calls)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
