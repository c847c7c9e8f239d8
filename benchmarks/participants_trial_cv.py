"""Within-block variability of simulated trials: a 20/8/8 study's people, 3 trials per
condition (LCCA with the shipped estimator, or NOTES); per measure, the mean over blocks
of the block's SD over its mean, and how many blocks repeat a value exactly.

    nice -n 10 python benchmarks/participants_trial_cv.py OUT.json [--task notes]
"""

from __future__ import annotations

import argparse
import json

import pandas as pd

from study.campaign.unit import trial_seed
from study.protocol.default_estimator import load_estimator
from study.protocol.design import MAX_TRIAL_S
from study.protocol.tasks import get_task
from study.protocol.traits import simulated_participant
from study.protocol.trial_run import simulate_trial

MEASURES = {
    "lcca": ("completion_time_s", "peak_proximal_force_n", "peak_distal_force_n"),
    "notes": (
        "completion_time_s",
        "peak_push_n",
        "peak_pull_n",
        "peak_torque_demanded_n_m",
        "peak_tip_force_n",
    ),
}
GROUPS = {"outsider": 20, "novice": 8, "expert": 8}


def main(out: str, task: str) -> None:
    the_task = get_task(task)
    context, estimator = the_task.session_context(), load_estimator() if task == "lcca" else None
    measures = MEASURES[task]
    rows = []
    for group, n in GROUPS.items():
        for k in range(n):
            code = f"{group}{k}"
            person = simulated_participant(group, 100 + k + 1000 * len(group))
            for block, condition in enumerate(("VO", "HV"), start=1):
                for i in range(3):
                    seed = trial_seed(1, code, block, i)
                    s = simulate_trial(
                        the_task,
                        person,
                        condition,
                        seed,
                        MAX_TRIAL_S,
                        estimator=estimator,
                        context=context,
                    )
                    rows.append(
                        {
                            "code": code,
                            "condition": condition,
                            **{m: s.summary[m] for m in measures},
                        }
                    )
    trials = pd.DataFrame(rows)
    blocks = trials.groupby(["code", "condition"])
    report = {
        "data_source": "simulated",
        "task": task,
        "command": "nice -n 10 python benchmarks/participants_trial_cv.py "
        + (f"{out} --task {task}" if task != "lcca" else out),
        "groups": GROUPS,
        "trials_per_block": 3,
        "definition": "per measure: the mean over blocks of the block's SD (ddof 1) over "
        "its mean; blocks_with_equal: blocks in which two trials have the same value",
        "measures": {
            m: {
                "mean_cv": round(
                    float(blocks[m].agg(lambda v: v.std(ddof=1) / v.mean()).mean()), 4
                ),
                "blocks_with_equal": int(blocks[m].agg(lambda v: v.nunique() < len(v)).sum()),
                "blocks": int(blocks.ngroups),
            }
            for m in measures
        },
    }
    with open(out, "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out")
    parser.add_argument("--task", choices=sorted(MEASURES), default="lcca")
    args = parser.parse_args()
    main(args.out, args.task)
