"""Two checkouts' loop profiles (`loop_profile.py`) or trial speeds (`loop_speed.py`),
run alternately in one session, with medians and ratios: the machine's speed drifts
between days and with the other jobs on it, so only ratios from one run count.

    python benchmarks/loop_side_by_side.py BASELINE_CHECKOUT NEW_CHECKOUT \\
        --rounds 5 --out benchmarks/results/loop_profile.json [-- ARGS FOR THE BENCH]

Each round runs the baseline and then the new checkout (the order alternates from round
to round), each in a fresh process under the same nice level as this one.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import alternate  # the sibling module: these scripts run as python benchmarks/NAME.py

HERE = Path(__file__).resolve().parent


def _flatten(d: dict, prefix: str = "") -> dict[str, float]:
    out: dict[str, float] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out[f"{prefix}{k}"] = float(v)
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("baseline")
    parser.add_argument("new")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--bench", default="loop_profile.py")
    parser.add_argument("--out", type=Path, default=None)
    argv = sys.argv[1:]
    cut = argv.index("--") if "--" in argv else len(argv)
    args, rest = parser.parse_args(argv[:cut]), argv[cut + 1 :]
    runs: dict[str, list[dict[str, float]]] = {"baseline": [], "new": []}
    for r in range(args.rounds):
        order = [("baseline", args.baseline), ("new", args.new)]
        for label, checkout in order if r % 2 == 0 else order[::-1]:
            env = {**os.environ, "PYTHONPATH": str(Path(checkout).resolve())}
            load = os.getloadavg()[0]  # the other jobs sharing the cores, as it starts
            done = subprocess.run(
                [sys.executable, str(HERE / args.bench), *rest],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            row = _flatten(json.loads(done.stdout.strip().splitlines()[-1]))
            runs[label].append({**row, "load_avg_1min": load})
            print(f"round {r + 1}/{args.rounds} {label} done", file=sys.stderr)
    medians = alternate.medians(runs)
    ratios = {
        k: medians["baseline"][k] / medians["new"][k]
        for k in medians["new"]
        if k in medians["baseline"] and medians["new"][k] != 0
    }

    def nest(flat: dict[str, float]) -> dict:  # "trials.cpu_s" -> {"trials": {"cpu_s"}}
        out: dict = {}
        for key, value in flat.items():
            *parents, leaf = key.split(".")
            node = out
            for part in parents:
                node = node.setdefault(part, {})
            node[leaf] = value
        return out

    # rates (simulated s per CPU s) read the other way round: new / baseline, the
    # speed-up per simulated second whatever length each version's trials came out
    inverse = {
        k: medians["new"][k] / medians["baseline"][k]
        for k in medians["new"]
        if k in medians["baseline"] and medians["baseline"][k] != 0
    }
    medians = {label: nest(m) for label, m in medians.items()}
    ratios = nest(ratios)
    report = {
        "data": "simulated",
        "command": " ".join(["python", "benchmarks/loop_side_by_side.py", *sys.argv[1:]]),
        "bench": args.bench,
        "baseline": args.baseline,
        "new": args.new,
        "rounds": args.rounds,
        "nice": os.nice(0),
        "median": medians,
        "baseline_over_new": ratios,
        "new_over_baseline": nest(inverse),
        "runs": runs,
    }
    alternate.write_report(report, args.out)


if __name__ == "__main__":
    main()
