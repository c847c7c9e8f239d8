"""A shell command run for two checkouts alternately in one session: CPU seconds (user +
system, of the command and its children) and wall seconds per run, medians and ratios.

    python benchmarks/command_side_by_side.py BASELINE NEW --rounds 3 \\
        --out benchmarks/results/demo_side_by_side.json -- \\
        'study demo --quick --out {tmp}/demo'

In the command, `{tmp}` is a fresh folder per run and `{checkout}` the checkout; each run
has the checkout first on PYTHONPATH. `--json-key speed.realtime_factor_median` also
reads that key from the JSON file the command writes to `{tmp}/out.json` (also kept as
`json_value`, a key the docs' index can name).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import alternate  # the sibling module: these scripts run as python benchmarks/NAME.py
from alternate import timed


def _run(command: str, checkout: str, json_key: str | None) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "PYTHONPATH": str(Path(checkout).resolve())}
        done, row = timed(
            command.format(tmp=tmp, checkout=checkout),
            shell=True,
            env=env,
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            raise SystemExit(f"{command!r} failed for {checkout}:\n{done.stderr[-2000:]}")
        if json_key:
            value: object = json.loads((Path(tmp) / "out.json").read_text())
            for part in json_key.split("."):  # a number indexes a list
                value = value[int(part) if isinstance(value, list) else part]  # type: ignore[index]
            row[json_key] = float(value)  # type: ignore[arg-type]
            row["json_value"] = row[json_key]  # the same under a key without dots
        return row


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("baseline")
    parser.add_argument("new")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json-key", default=None)
    parser.add_argument("--out", type=Path, default=None)
    argv = sys.argv[1:]
    cut = argv.index("--")
    args, command = parser.parse_args(argv[:cut]), " ".join(argv[cut + 1 :])
    runs: dict[str, list[dict[str, float]]] = {"baseline": [], "new": []}
    for r in range(args.rounds):
        order = [("baseline", args.baseline), ("new", args.new)]
        for label, checkout in order if r % 2 == 0 else order[::-1]:
            runs[label].append(_run(command, checkout, args.json_key))
            print(f"round {r + 1}/{args.rounds} {label}: {runs[label][-1]}", file=sys.stderr)
    medians = alternate.medians(runs)
    report = {
        "command": command,
        "driver": " ".join(["python", "benchmarks/command_side_by_side.py", *argv]),
        "baseline": args.baseline,
        "new": args.new,
        "rounds": args.rounds,
        "nice": os.nice(0),
        "median": medians,
        "new_over_baseline": {
            k: medians["new"][k] / medians["baseline"][k] for k in medians["new"]
        },
        "runs": runs,
    }
    alternate.write_report(report, args.out)


if __name__ == "__main__":
    main()
