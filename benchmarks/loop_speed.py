"""Simulated LCCA trials per CPU second for one checkout, as JSON on stdout.

Run it with a checkout first on PYTHONPATH (this file imports only what every version
of haptic-study has), so that two versions are timed by the same code:

    PYTHONPATH=/path/to/checkout python benchmarks/loop_speed.py --trials 8 --max-s 60

It runs outsiders' HV and VO trials (seeds 0, 1, ...) with the shipped estimator after
one warm-up trial that loads or compiles the kernel, and reports simulated seconds per
CPU second (`time.process_time`) and per wall second, per trial and in total.
`--samples FILE` also saves every trial's samples (npz), to compare two versions.
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


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--max-s", type=float, default=60.0)
    parser.add_argument("--samples", default=None)
    args = parser.parse_args()
    from study.protocol.default_estimator import load_estimator

    lcca_loop, simulated_participant, SimulatedParticipant = _lcca_parts()
    from teleop_core.phantom.lcca import LccaPhantom

    estimator = load_estimator(None)
    phantom = LccaPhantom()

    def trial(seed: int, condition: str):  # the loop alone, without the measures
        traits = simulated_participant("outsider", seed)
        loop = lcca_loop(condition, seed, estimator, None, phantom)
        participant = SimulatedParticipant(traits, phantom, give_up_s=args.max_s)
        return loop.run(args.max_s, participant)

    trial(0, "HV")  # warm-up: kernel loaded or compiled
    rows, saved = [], {}
    for i in range(args.trials):
        seed, condition = i // 2, ("HV", "VO")[i % 2]
        cpu, wall = time.process_time(), time.perf_counter()
        result = trial(seed, condition)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        sim_s = float(result.samples[-1, 0]) if len(result.samples) else 0.0
        rows.append(
            {"seed": seed, "condition": condition, "sim_s": sim_s, "cpu_s": cpu, "wall_s": wall}
        )
        saved[f"{condition}_{seed}"] = result.samples
    if args.samples:
        np.savez(args.samples, **saved)
    sim = sum(r["sim_s"] for r in rows)
    out = {
        "checkout": os.environ.get("PYTHONPATH", ""),
        "sim_s": sim,
        "cpu_s": sum(r["cpu_s"] for r in rows),
        "wall_s": sum(r["wall_s"] for r in rows),
        "sim_per_cpu_s": sim / sum(r["cpu_s"] for r in rows),
        "sim_per_wall_s": sim / sum(r["wall_s"] for r in rows),
        "trials": rows,
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
