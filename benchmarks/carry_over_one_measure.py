"""What the carry-overs on one measure (`force_carry_over`, `time_carry_over`,
`study.protocol.participant_effects`) do to LCCA's measures on its own simulator:
SIMULATED.

People drawn from the hand-set profiles (PEOPLE per group), each run in the second
block after the other condition (VO after HV, HV after VO) with and without the effect,
the same trial seeds in both (paired: the difference is the effect, not the draw). Per
family and condition: the geometric-mean change of each measure in per cent and its
standard error (of the mean paired log ratio). Ideal sensor (no force estimator): the
effect is the person's, not the estimate's.

    nice -n 10 python benchmarks/carry_over_one_measure.py OUT.json [--people 32] \
        [--seed 7] [--share-force 0.5] [--share-time 0.2]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from study.protocol.participant_effects import (
    FAMILIES,
    ParticipantEffect,
    TrialPlace,
    apply_effects,
)
from study.protocol.tasks import get_task
from study.protocol.traits import GROUPS, ParticipantTraits, draw_traits
from study.protocol.trial_run import simulate_trial

MEASURES = ("completion_time_s", "peak_proximal_force_n", "peak_distal_force_n")
REPEATS = 2
"""Trial seeds per person and condition."""


def change(
    people: list[ParticipantTraits], effect: ParticipantEffect, condition: str
) -> dict[str, dict[str, float]]:
    """measure -> {change_pct, se_pct}: the paired geometric-mean change."""
    other = "HV" if condition == "VO" else "VO"
    place = TrialPlace(position=3, block=1, condition=condition, first_condition=other)
    logs = []
    for i, person in enumerate(people):
        changed = apply_effects(person, (effect,), place)
        for r in range(REPEATS):
            seed = 1000 * i + r
            a = simulate_trial(get_task("lcca"), person, condition, seed, 180.0).summary
            b = simulate_trial(get_task("lcca"), changed, condition, seed, 180.0).summary
            logs.append([math.log(b[m] / a[m]) for m in MEASURES])
    d = np.array(logs)
    se = d.std(axis=0, ddof=1) / math.sqrt(len(d))
    return {
        m: {"change_pct": 100 * math.expm1(d[:, k].mean()), "se_pct": 100 * se[k]}
        for k, m in enumerate(MEASURES)
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--people", type=int, default=32, help="people per group")
    parser.add_argument("--seed", type=int, default=7, help="seed of the people's draws")
    parser.add_argument("--share-force", type=float, default=0.5)
    parser.add_argument("--share-time", type=float, default=0.2)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    people = [draw_traits(g, rng) for g in GROUPS for _ in range(args.people)]
    report: dict[str, Any] = {
        "data_source": "simulated",
        "people_per_group": args.people,
        "trials_per_person_and_condition": REPEATS,
        "seed": args.seed,
    }
    for family, share in (
        ("force_carry_over", args.share_force),
        ("time_carry_over", args.share_time),
    ):
        effect = ParticipantEffect(family, {name: share for name in FAMILIES[family]})
        report[family] = {"share": share}
        for condition in ("VO", "HV"):
            report[family][condition] = result = change(people, effect, condition)
            print(
                family,
                condition,
                ", ".join(
                    f"{m} {v['change_pct']:+.1f} % (SE {v['se_pct']:.1f})"
                    for m, v in result.items()
                ),
                flush=True,
            )
    args.out.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
