"""`study bench participants --probes` on several seeds, one emulator shared by them
(it depends on the fit's settings only), and the coverage of the fitted means' 95 %
intervals on that emulator with the first seed's fit; SIMULATED throughout.

    nice -n 10 python benchmarks/participants_probes.py OUT_DIR --seeds 11 12 13 \
        --design 320 --repeats 2 --check 24 --bootstrap 40 --truth-people 60 --coverage 50

writes OUT_DIR/participants_probes.json and .md (per seed: the bench's report and its
markdown), and OUT_DIR/participants_coverage.json when --coverage is above 0.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from study.analysis.participant_fit.coverage import coverage
from study.analysis.participant_fit.fit import FitSettings, build_emulator
from study.bench.participants import markdown, run_participants_bench, truth_profiles
from study.protocol.traits import TRAITS
from teleop_core.progress import as_step

GROUPS = {"outsider": 20, "novice": 8, "expert": 8}


def _status(step: str, k: int = 0, n: int = 0) -> None:
    print(f"{time.strftime('%H:%M:%S')} {step} {k}/{n}", file=sys.stderr, flush=True)


def _outside(line: str) -> int:
    """How many of the emulator check's predictions lie outside, from its line."""
    found = re.search(r"in (\d+) of \d+ summaries", line)
    return int(found.group(1)) if found else 0


def _count(text: str) -> int:
    """The k of a report's 'k of n'."""
    return int(text.split(" of ")[0])


def _summary(report: dict[str, Any]) -> dict[str, Any]:
    ratios = report["identification_ratio"]
    return {
        "seed": report["seed"],
        "identifiable": len(report["identifiable"]),
        "largest_identification_ratio": max(ratios.values()),
        "within_15pct_of_truth": report["recovery_within"],
        "within_15pct_of_study_people": report["recovery_within_study_people"],
        "vo_hv_intervals_holding_truth": sum(d["within"] for d in report["differences"]),
        "vo_hv_simulated_people_intervals_holding_truth": sum(
            d.get("simulated_within", d["within"]) for d in report["differences"]
        ),
        "emulator_check": report["emulator_check"],
        "emulator_outside": _outside(report["emulator_check"]),
        "emulator_outside_people_only": report.get("emulator_check_outside_people_only"),
        "emulator_outside_at_best_fit": report.get("emulator_check_outside_best_fit"),
        "fit_seconds": report["fit_seconds"],
        "targets_met": {
            "every_ratio_below_0_5": max(ratios.values()) < 0.5,
            "at_least_19_of_21_within_study_people": _count(report["recovery_within_study_people"])
            >= 19,
            "vo_hv_6_of_6": all(d["within"] for d in report["differences"]),
            "emulator_at_most_2_of_27": _outside(report["emulator_check"]) <= 2,
        },
    }


def summarise(out: Path) -> None:
    """Recompute the JSON's `summary` from its seeds' reports (a run written by an
    earlier version of this script)."""
    path = out / "participants_probes.json"
    data = json.loads(path.read_text())
    data["summary"] = [_summary(r) for r in data["seeds"]]
    data["summary_by"] = f"python benchmarks/participants_probes.py {out} --summarise"
    path.write_text(json.dumps(data, indent=1, default=str))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("out", type=Path)
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    parser.add_argument("--design", type=int, default=320)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--check", type=int, default=24)
    parser.add_argument("--bootstrap", type=int, default=40)
    parser.add_argument("--truth-people", type=int, default=60)
    parser.add_argument("--coverage", type=int, default=0)
    parser.add_argument(
        "--emulator-cache",
        type=Path,
        help="pickle of the emulator: loaded if present, else written",
    )
    parser.add_argument(
        "--coverage-only",
        action="store_true",
        help="only the coverage, with OUT/participants_probes.json's first seed",
    )
    parser.add_argument("--summarise", action="store_true", help="only recompute the summary")
    parser.add_argument(
        "--coverage-seed", type=int, help="the coverage's own seed (default: the first seed)"
    )
    parser.add_argument(
        "--combine",
        nargs="+",
        type=Path,
        help="merge these coverage JSONs (runs with different --coverage-seed) into "
        "OUT/participants_coverage.json",
    )
    args = parser.parse_args()
    if args.summarise:
        summarise(args.out)
        return
    if args.combine:
        combine(args.out, args.combine)
        return
    command = "nice -n 10 python benchmarks/participants_probes.py " + " ".join(sys.argv[1:])
    settings = FitSettings(
        design=args.design,
        repeats=args.repeats,
        check=args.check,
        bootstrap=args.bootstrap,
        jobs=2,
        seed=0,
    )
    start = time.monotonic()
    if args.emulator_cache is not None and args.emulator_cache.exists():
        emulator = pickle.loads(args.emulator_cache.read_bytes())
    else:
        emulator = build_emulator("lcca", settings, _status)
        if args.emulator_cache is not None:
            args.emulator_cache.write_bytes(pickle.dumps(emulator))
    emulator_s = time.monotonic() - start
    args.out.mkdir(parents=True, exist_ok=True)
    if args.coverage_only:
        first = json.loads((args.out / "participants_probes.json").read_text())["seeds"][0]
        _coverage(emulator, first, settings, args.coverage, command, args.out, args.coverage_seed)
        return
    reports: list[dict[str, Any]] = []
    for seed in args.seeds:
        report = run_participants_bench(
            GROUPS,
            3,
            settings,
            args.truth_people,
            seed,
            None,
            _status,
            probes=True,
            emulator=emulator,
        )
        report["seed"] = seed
        reports.append(report)
        out = {
            "data_source": "simulated",
            "command": command,
            "emulator_seconds": round(emulator_s, 1),
            "load_average_end": [round(x, 2) for x in os.getloadavg()],
            "summary": [_summary(r) for r in reports],
            "seeds": reports,
        }
        (args.out / "participants_probes.json").write_text(json.dumps(out, indent=1, default=str))
        text = [f"Command: `{command}`. SIMULATED data throughout.", ""]
        for r in reports:
            text += [f"## Seed {r['seed']}", "", markdown(r)]
        (args.out / "participants_probes.md").write_text("\n".join(text))
    if args.coverage:
        _coverage(emulator, reports[0], settings, args.coverage, command, args.out)


def _coverage(
    emulator: Any,
    first: dict[str, Any],
    settings: FitSettings,
    studies: int,
    command: str,
    out: Path,
    seed: int | None = None,
) -> None:
    """The coverage on the shared emulator with the first seed's free traits and probe
    SEs (`participant_fit.coverage`)."""
    start = time.monotonic()
    free = [TRAITS.index(t) for t in first["identifiable"]]
    weak = [TRAITS.index(t) for t in first["shrunk_to_prior"]]
    probe_se = {g: np.array(v, dtype=float) for g, v in first["probe_se"].items()}
    covered = coverage(
        emulator,
        truth_profiles(first["truth_shift_prior_sds"]),
        GROUPS,
        3.0,
        free,
        studies,
        settings.bootstrap,
        first["seed"] if seed is None else seed,
        weak,
        as_step(_status, "coverage: study"),
        probe_se,
    )
    covered.update(
        {
            "data_source": "simulated",
            "command": command,
            "seed": first["seed"],
            "coverage_seed": first["seed"] if seed is None else seed,
            "free": first["identifiable"],
            "probe_se": first["probe_se"],
            "seconds": round(time.monotonic() - start, 1),
            "interval": "expanded percentile (estimate.expanded_interval)",
        }
    )
    name = "participants_coverage.json" if seed is None else f"participants_coverage_{seed}.json"
    (out / name).write_text(json.dumps(covered, indent=1))


def combine(out: Path, paths: list[Path]) -> None:
    """One coverage report from runs with different coverage seeds: the studies pooled."""
    runs = [json.loads(p.read_text()) for p in paths]
    per: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for run in runs:
        for row in run["per_trait"]:
            per.setdefault((row["group"], row["trait"]), []).append(row)
    studies = sum(r["studies"] for r in runs)
    hits = sum(r["coverage"] * r["intervals"] for r in runs)
    intervals = sum(r["intervals"] for r in runs)
    share = hits / intervals
    merged = {
        **{k: v for k, v in runs[0].items() if k not in ("per_trait", "seconds")},
        "studies": studies,
        "intervals": intervals,
        "coverage": share,
        "met": bool(runs[0]["target"][0] <= share <= runs[0]["target"][1]),
        "coverage_seed": [r["coverage_seed"] for r in runs],
        "seconds": [r["seconds"] for r in runs],
        "commands": [r["command"] for r in runs],
        "per_trait": [
            {
                "group": g,
                "trait": t,
                "studies": sum(r["studies"] for r in rows),
                "coverage": sum(r["coverage"] * r["studies"] for r in rows)
                / sum(r["studies"] for r in rows),
                "error_mean_boot_sds": sum(r["error_mean_boot_sds"] * r["studies"] for r in rows)
                / sum(r["studies"] for r in rows),
            }
            for (g, t), rows in per.items()
        ],
    }
    merged.pop("command", None)
    (out / "participants_coverage.json").write_text(json.dumps(merged, indent=1))


if __name__ == "__main__":
    main()
