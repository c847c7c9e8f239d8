"""`study analyze` against the same analysis in R (`analyze_r.R`), alternately in one run.

    python benchmarks/analyze_vs_r.py --db demo/demo.db --rounds 5 \\
        --out benchmarks/results/analyze_vs_r.json

The participant means R reads are written from the database first (the long CSV of
`study.analysis.frames.participant_means`: participant, group, task, condition, measure,
value; the same file format as tests/data/demo_seed1_means.csv). Each round runs
`study analyze --db DB --out TMP` and `Rscript benchmarks/analyze_r.R MEANS.csv OUT.txt`
(the order alternating), each a fresh process; CPU seconds (user + system of the process
and its children) and wall seconds, medians, and Python's over R's; the machine's 1-minute
load average at the start and the end.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import alternate  # the sibling module: these scripts run as python benchmarks/NAME.py
from alternate import timed

HERE = Path(__file__).resolve().parent


def _timed(command: list[str]) -> dict[str, float]:
    return timed(command, check=True, capture_output=True)[1]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--db", required=True)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    from sqlalchemy import create_engine

    from study.analysis.frames import participant_means, tlx_frame, trial_frame

    runs: dict[str, list[dict[str, float]]] = {"python": [], "r": []}
    load_start = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        engine = create_engine(f"sqlite:///{args.db}")
        means = participant_means(trial_frame(engine), tlx_frame(engine))
        engine.dispose()
        csv = Path(tmp) / "means.csv"
        means.to_csv(csv, index=False)
        python = [sys.executable, "-m", "study.cli", "analyze", "--db", args.db]
        r = ["Rscript", str(HERE / "analyze_r.R"), str(csv)]
        for i in range(args.rounds):
            jobs = [
                ("python", [*python, "--out", f"{tmp}/py{i}"]),
                ("r", [*r, f"{tmp}/r{i}.txt"]),
            ]
            for label, command in jobs if i % 2 == 0 else jobs[::-1]:
                runs[label].append(_timed(command))
                print(f"round {i + 1}/{args.rounds} {label}: {runs[label][-1]}", file=sys.stderr)
    medians = alternate.medians(runs)
    report = {
        "command": " ".join(["python", "benchmarks/analyze_vs_r.py", *sys.argv[1:]]),
        "rounds": args.rounds,
        "participants": int(means["participant"].nunique()),
        "nice": os.nice(0),
        "load_average_1min": {"start": load_start, "end": os.getloadavg()[0]},
        "median": medians,
        "python_over_r": {k: medians["python"][k] / medians["r"][k] for k in medians["r"]},
        "runs": runs,
    }
    alternate.write_report(report, args.out)


if __name__ == "__main__":
    main()
