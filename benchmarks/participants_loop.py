"""The loop on the people at the issue's size (SIMULATED): studies of 20/8/8 people
from the hand-set profiles, 3 trials per condition, clean and with a practice effect,
a carry-over or a fatigue injected, each searched by `participant_fit.effects.search`.

    nice -n 5 python benchmarks/participants_loop.py OUT.json [SEED ...] [--cache DIR]
    python benchmarks/participants_loop.py --merge OUT.json PART.json ...

(`--merge`: the studies of several runs, e.g. one per seed run side by side, in one
report.)

The emulator: 200 settings x 1 trial per condition (seed 3, 60 s cap), as the tests';
the studies: `simulate_people` with the study seed given (31 by default); a study with
an effect holds the same people and trial seeds as the clean one of its seed. The
report holds, per study, the structure found, the family named, its parameters with
their 95 % intervals, the held-out prediction error before and after (and per
measure), the cells' noise floor, the error of the model given the injected effect
instead of fitting it (`known`: what the right effect reaches on these people), and
the seconds taken.
"""

from __future__ import annotations

import dataclasses
import json
import pickle
import sys
import time
from pathlib import Path

from study.analysis.participant_fit import effects
from study.analysis.participant_fit.fit import (
    FitSettings,
    build_emulator,
    plan_traits,
    read_data,
    simulate_people,
)
from study.protocol.participant_effects import ParticipantEffect
from study.protocol.traits import PROFILES

SETTINGS = FitSettings(design=200, repeats=1, check=4, bootstrap=10, jobs=2, seed=3, max_s=60.0)
SIZES = {"outsider": 20, "novice": 8, "expert": 8}
INJECTED = {
    "clean": (),
    "practice": (ParticipantEffect("practice", {"slowing": 0.5, "decay_trials": 2.0}),),
    "carry_over": (ParticipantEffect("carry_over", {"vo_after_hv": 0.3, "hv_after_vo": 0.0}),),
    "fatigue": (ParticipantEffect("fatigue", {"rate": 0.05}),),
}
TARGET = {"clean": None, "practice": 0.30, "carry_over": 0.10, "fatigue": 0.0}


def _cached(path: Path | None, make):
    if path is not None and path.exists():
        return pickle.loads(path.read_bytes())
    value = make()
    if path is not None:
        path.write_bytes(pickle.dumps(value))
    return value


def study(seed: int, name: str):
    frames = []
    for group, n in SIZES.items():
        s = dataclasses.replace(SETTINGS, seed=seed + 97 * len(frames))
        f = simulate_people(
            "lcca", {group: [PROFILES[group]]}, n, 3, s, lambda *_: None, INJECTED[name]
        )
        f["participant"] = group[0].upper() + f["participant"]
        frames.append(f)
    import pandas as pd

    return pd.concat(frames, ignore_index=True)


def merge(out: Path, parts: list[Path]) -> None:
    reports = [json.loads(p.read_text()) for p in parts]
    report = reports[0]
    report["studies"] = [row for r in reports for row in r["studies"]]
    out.write_text(json.dumps(report, indent=1, default=float) + "\n")


def main(argv: list[str]) -> None:
    if argv[:1] == ["--merge"]:
        merge(Path(argv[1]), [Path(a) for a in argv[2:]])
        return
    cache = None
    if "--cache" in argv:
        i = argv.index("--cache")
        cache = Path(argv[i + 1])
        cache.mkdir(parents=True, exist_ok=True)
        argv = argv[:i] + argv[i + 2 :]
    out = Path(argv[0])
    seeds = [int(a) for a in argv[1:]] or [31]
    emulator = _cached(cache and cache / "emulator.pkl", lambda: build_emulator("lcca", SETTINGS))
    rows = []
    for seed in seeds:
        for name in INJECTED:
            trials = _cached(
                cache and cache / f"{name}_{seed}.pkl", lambda s=seed, n=name: study(s, n)
            )
            start = time.monotonic()
            data = read_data(trials, "lcca", emulator, "simulated")
            plan = plan_traits(emulator, data, SETTINGS)
            found = effects.search(
                data.trials, emulator, plan.free, plan.weak, SETTINGS.seed, bootstrap=50
            )
            known = None
            if INJECTED[name]:
                known = effects.prediction_error(
                    data.trials, emulator, [], plan.free, plan.weak, SETTINGS.seed, INJECTED[name]
                )
            named = [e.family for e in found.effects]
            target = TARGET[name]
            rows.append(
                {
                    "seed": seed,
                    "injected": name,
                    "named": named,
                    "effects": [e.to_dict() for e in found.effects],
                    "structure_before": effects.describe(found.before),
                    "tried": found.tried,
                    "error_before": found.error_before.error,
                    "error_after": found.error_after.error,
                    "by_measure_before": found.error_before.by_measure,
                    "by_measure_after": found.error_after.by_measure,
                    "cells": found.error_before.cells,
                    "noise_floor": found.error_before.noise_floor,
                    "reduction": found.reduction(),
                    "error_known": None if known is None else known.error,
                    "reduction_known": None
                    if known is None
                    else 1.0 - known.error / found.error_before.error,
                    "by_measure_known": None if known is None else known.by_measure,
                    "verdict": found.verdict,
                    "met": (named == [] and found.verdict == "white")
                    if target is None
                    else (
                        named[:1] == [name]
                        and (found.reduction() >= target if target else found.reduction() > 0)
                    ),
                    "seconds": round(time.monotonic() - start, 1),
                    "line": found.line(),
                }
            )
            print(json.dumps(rows[-1]["line"]), rows[-1]["met"], flush=True)
    report = {
        "data_source": "simulated",
        "sizes": SIZES,
        "trials_per_condition": 3,
        "emulator": {
            "design": SETTINGS.design,
            "repeats": SETTINGS.repeats,
            "seed": 3,
            "max_s": SETTINGS.max_s,
        },
        "injected": {k: [e.to_dict() for e in v] for k, v in INJECTED.items()},
        "targets": {
            "practice": "named, held-out error >= 30 % lower",
            "fatigue": "named, held-out error lower",
            "carry_over": "named, held-out error >= 10 % lower",
            "clean": "nothing added, verdict white",
        },
        "definition": effects.DEFINITION,
        "studies": rows,
    }
    out.write_text(json.dumps(report, indent=1, default=float) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
