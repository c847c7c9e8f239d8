"""`study analyze` against the same analysis in R, alternately in one run.

    python benchmarks/analyze_vs_r.py --db demo/demo.db --rounds 5 \\
        --out benchmarks/results/analyze_vs_r.json

The study is exported first (`study export`); R's side is the export how-to's script
(`docs/how-to/reproduce.R`: the within-group tests with coin's exact signed rank, afex's
mixed ANOVA, lmerTest's mixed model with Satterthwaite df, emmeans's marginal means and
the crossover's checks), reading that export alone. Each round runs
`study analyze --db DB --out TMP` and `Rscript docs/how-to/reproduce.R EXPORT OUT`
(the order alternating), each a fresh process; CPU seconds (user + system of the process
and its children) and wall seconds, medians, and Python's over R's; the machine's 1-minute
load average at the start and the end.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import alternate  # the sibling module: these scripts run as python benchmarks/NAME.py
from alternate import timed

HERE = Path(__file__).resolve().parent


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def _timed(command: list[str]) -> dict[str, float]:
    return timed(command, check=True, capture_output=True)[1]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--db", required=True)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    runs: dict[str, list[dict[str, float]]] = {"python": [], "r": []}
    load_start = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        study = [sys.executable, "-m", "study.cli"]
        export = Path(tmp) / "export"
        subprocess.run([*study, "export", "--db", args.db, "--out", str(export)], check=True)
        participants = len({row["participant"] for row in _rows(export / "trials.csv")})
        python = [*study, "analyze", "--db", args.db]
        r = ["Rscript", str(HERE.parent / "docs" / "how-to" / "reproduce.R"), str(export)]
        for i in range(args.rounds):
            jobs = [
                ("python", [*python, "--out", f"{tmp}/py{i}"]),
                ("r", [*r, f"{tmp}/r{i}"]),
            ]
            for label, command in jobs if i % 2 == 0 else jobs[::-1]:
                runs[label].append(_timed(command))
                print(f"round {i + 1}/{args.rounds} {label}: {runs[label][-1]}", file=sys.stderr)
    medians = alternate.medians(runs)
    report = {
        "command": " ".join(["python", "benchmarks/analyze_vs_r.py", *sys.argv[1:]]),
        "rounds": args.rounds,
        "participants": participants,
        "nice": os.nice(0),
        "load_average_1min": {"start": load_start, "end": os.getloadavg()[0]},
        "median": medians,
        "python_over_r": {k: medians["python"][k] / medians["r"][k] for k in medians["r"]},
        "runs": runs,
    }
    alternate.write_report(report, args.out)


if __name__ == "__main__":
    main()
