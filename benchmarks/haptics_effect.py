"""What haptics changes in expectation: SIMULATED people of each group drawn from the
hand-set profiles (`study.protocol.traits.PROFILES`, as `study demo` draws them), each
running LCCA trials in VO and in HV through the simulator itself (`Task.simulate`: the
loop, the simulated participant and the shipped estimator, as `study simulate`, the
campaigns and the participant fit run a trial; not the participant fit's emulator).

Per group and condition: the mean over people of each person's mean peak proximal
force, peak distal force and completion time (every trial, failed ones at the time they
ended, as `study analyze` takes them), and the relative change HV against VO (the ratio
of the group means, minus 1) with a 95 % percentile bootstrap interval over people
(the people resampled with both their conditions). A person's VO and HV trials of one
repeat share the trial seed (common random numbers: the same trial-to-trial state and
phantom draws), so the difference is the condition's; the expectation is the same as
with the independent seeds of a study's sessions, the interval narrower.

    nice -n 10 python benchmarks/haptics_effect.py --per-group 400 --jobs 2

writes OUT/haptics_effect.json and OUT/haptics_effect.md (OUT: benchmarks/results);
progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

MEASURES = {
    "peak_proximal_force_n": "peak proximal force (N)",
    "peak_distal_force_n": "peak distal force (N)",
    "completion_time_s": "completion time (s)",
}
CONDITIONS = ("VO", "HV")
TASK = "lcca"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="SIMULATED: peak forces and completion time of LCCA trials in VO and HV "
        "per group, for people drawn from the hand-set profiles, run through the simulator.",
    )
    parser.add_argument(
        "--per-group", type=int, default=400, help="people per group [default: 400]"
    )
    parser.add_argument(
        "--trials", type=int, default=1, help="trials per person and condition [default: 1]"
    )
    parser.add_argument("--jobs", type=int, default=2, help="worker processes [default: 2]")
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of the people's draw [default: 0]"
    )
    parser.add_argument(
        "--bootstrap", type=int, default=4000, help="bootstrap resamples [default: 4000]"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("benchmarks/results"),
        help="folder for haptics_effect.json and .md [default: benchmarks/results]",
    )
    parser.add_argument(
        "--name", default="haptics_effect", help="file stem [default: haptics_effect]"
    )
    args = parser.parse_args(argv)
    for name in ("per_group", "trials", "jobs", "bootstrap"):
        if getattr(args, name) < 1:
            parser.exit(
                2, f"--{name.replace('_', '-')} {getattr(args, name)}; expected an integer >= 1\n"
            )
    if not args.out.is_dir():
        parser.exit(2, f"--out {args.out}; expected an existing folder\n")
    return args


def draw_people(per_group: int, seed: int) -> list[dict[str, Any]]:
    """`per_group` people of each group from `PROFILES`, by `draw_traits` as a demo's
    sessions draw them; half of them VO-first (no participant effects are applied, so
    the order changes nothing)."""
    from study.protocol.traits import PROFILES, draw_traits

    rng = np.random.default_rng([seed, 0x4A9])
    people = [draw_traits(g, rng).to_dict() for g in PROFILES for _ in range(per_group)]
    return [{**p, "first": CONDITIONS[i % 2]} for i, p in enumerate(people)]


def stderr_progress(start: float) -> Any:
    shown = {"at": 0.0}

    def progress(step: str, k: int, n: int) -> None:
        now = time.monotonic()
        if k < n and now - shown["at"] < 5.0:
            return
        shown["at"] = now
        elapsed = now - start
        eta = elapsed / k * (n - k) if k else float("nan")
        print(
            f"haptics_effect: {step} {k}/{n} people, {elapsed:.0f} s, about {eta:.0f} s left",
            file=sys.stderr,
            flush=True,
        )

    return progress


def person_means(trials: pd.DataFrame, people: list[dict[str, Any]]) -> pd.DataFrame:
    """One row per person: group, and each measure's mean per condition (`M/VO`, `M/HV`)."""
    means = trials.groupby(["setting", "condition"])[list(MEASURES)].mean().unstack("condition")
    means.columns = [f"{m}/{c}" for m, c in means.columns]
    means["group"] = [people[i]["group"] for i in means.index]
    return means


def relative_change(
    vo: np.ndarray, hv: np.ndarray, resamples: int, rng: np.random.Generator
) -> dict[str, float]:
    """HV mean over VO mean minus 1, with a 95 % percentile bootstrap interval over
    people (index pairs resampled together)."""
    n = len(vo)
    idx = rng.integers(0, n, size=(resamples, n))
    boot = hv[idx].mean(axis=1) / vo[idx].mean(axis=1) - 1.0
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return {
        "vo_mean": float(vo.mean()),
        "hv_mean": float(hv.mean()),
        "relative_change": float(hv.mean() / vo.mean() - 1.0),
        "ci95_low": float(lo),
        "ci95_high": float(hi),
    }


def summarise(
    trials: pd.DataFrame, people: list[dict[str, Any]], resamples: int, seed: int
) -> dict[str, Any]:
    rng = np.random.default_rng([seed, 0xB007])
    means = person_means(trials, people)
    group_of = np.array([p["group"] for p in people])[trials["setting"].to_numpy()]
    out: dict[str, Any] = {}
    for group in dict.fromkeys(p["group"] for p in people):
        g = means[means["group"] == group]
        in_group = trials[group_of == group]
        out[group] = {
            "people": len(g),
            "success_rate": {
                c: float(in_group.loc[in_group["condition"] == c, "success"].mean())
                for c in CONDITIONS
            },
            **{
                m: relative_change(g[f"{m}/VO"].to_numpy(), g[f"{m}/HV"].to_numpy(), resamples, rng)
                for m in MEASURES
            },
        }
    return out


def markdown(report: dict[str, Any]) -> str:
    lines = [
        "# What haptics changes, in expectation (SIMULATED)",
        "",
        f"Command: `{report['command']}`",
        "",
        f"SIMULATED people: {report['per_group']} per group from the hand-set profiles, "
        f"{report['trials_per_condition']} LCCA trial(s) per condition each, run through the "
        "simulator (the loop, the simulated participant, the shipped estimator). "
        f"Interval: {report['interval']}.",
        "",
        f"Run {report['started_utc']}, {report['wall_s']:.0f} s wall, "
        f"{report['cpu_s']:.0f} CPU s (this process and its workers), "
        f"load average {report['load_average_start'][0]:.2f} at the start, "
        f"{report['load_average_end'][0]:.2f} at the end (1 min).",
        "",
        "| group | measure | VO | HV | HV vs VO | 95 % interval |",
        "|---|---|---|---|---|---|",
    ]
    for group, g in report["groups"].items():
        for m, label in MEASURES.items():
            r = g[m]
            lines.append(
                f"| {group} | {label} | {r['vo_mean']:.3f} | {r['hv_mean']:.3f} | "
                f"{100 * r['relative_change']:+.1f} % | "
                f"{100 * r['ci95_low']:+.1f} to {100 * r['ci95_high']:+.1f} % |"
            )
    lines += ["", "Trials that reached the goal:", ""]
    lines += [
        f"- {group}: VO {100 * g['success_rate']['VO']:.1f} %, "
        f"HV {100 * g['success_rate']['HV']:.1f} %"
        for group, g in report["groups"].items()
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    from study.analysis.participant_fit.simulate import simulate_settings
    from study.protocol.design import MAX_TRIAL_S

    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    load_start = os.getloadavg()
    start = time.monotonic()
    people = draw_people(args.per_group, args.seed)
    trials = simulate_settings(
        TASK,
        people,
        args.trials,
        args.jobs,
        MAX_TRIAL_S,
        stderr_progress(start),
        salt="fit",  # VO and HV of a person's repeat share the trial seed
    )
    wall = time.monotonic() - start
    cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
    own = resource.getrusage(resource.RUSAGE_SELF)
    report = {
        "data_source": "SIMULATED",
        "command": "nice -n 10 python benchmarks/haptics_effect.py "
        + shlex.join(sys.argv[1:] if argv is None else argv),
        "started_utc": started,
        "task": TASK,
        "per_group": args.per_group,
        "trials_per_condition": args.trials,
        "seed": args.seed,
        "jobs": args.jobs,
        "profiles": "study.protocol.traits.PROFILES (hand-set)",
        "simulator": "Task.simulate through study.analysis.participant_fit.simulate."
        "simulate_settings (shipped estimator), common trial seeds across VO and HV",
        "measure_definition": "per person the mean over their trials in a condition (all "
        "trials, failed ones included); per group the mean over people; relative_change = "
        "HV mean / VO mean - 1",
        "interval": f"95 % percentile bootstrap over people ({args.bootstrap} resamples, "
        "each person's VO and HV resampled together)",
        "wall_s": round(wall, 1),
        "cpu_s": round(
            cpu.ru_utime + cpu.ru_stime + own.ru_utime + own.ru_stime,
            1,
        ),
        "load_average_start": [round(x, 2) for x in load_start],
        "load_average_end": [round(x, 2) for x in os.getloadavg()],
        "groups": summarise(trials, people, args.bootstrap, args.seed),
    }
    json_path = args.out / f"{args.name}.json"
    json_path.write_text(json.dumps(report, indent=1) + "\n")
    (args.out / f"{args.name}.md").write_text(markdown(report))
    print(f"SIMULATED: wrote {json_path} and {json_path.with_suffix('.md')} ({wall:.0f} s)")


if __name__ == "__main__":
    main()
