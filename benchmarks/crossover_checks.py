"""How often the crossover's checks (`study.analysis.crossover.design_checks`, the
`design_checks` of `analysis.json`) add a term to a study that has none, and how often
they find a planted period effect and carry-over: SIMULATED studies, drawn here.

Each scenario is an AB/BA crossover of one task (LCCA: completion time and the two peak
forces), condition orders alternating within each group, drawn with numpy:

- `normal`: 20/8/8, three trials a block, completion time = 30 s + group + HV (-2 s) +
  participant (sd 3 s) + noise (sd 3 s); forces normal around their means;
- `lognormal`: 11/5/3, two trials a block, every measure log-normal (a participant's
  log factor sd 0.25, a trial's 0.2), as completion times and peak forces are;
- `one_trial`: 20/8/8, one trial a block (no trial position to test), normal.

Without planted effects, the share of studies with any term added is the checks'
family-wise error rate (Holm over every check of the study, target at most 5 %). With
`--period 0.1 --carry-over 0.2` (shares of the mean completion time, planted in the
completion time only), the share where both are added is the checks' power; beside it
the closed-form power of the carry-over's between-participant t test at Holm's level
(`carry_over_power`): what the standard test of a carry-over reaches in these designs.

Each share comes with its exact (Clopper-Pearson) 95 % interval and the most a rate of
5 % shows at that many studies in 95 % of runs (`ceiling`): a procedure whose true rate
is 5 % is seen above 5 % in about half of the runs, so the target is read against the
ceiling (a one-sided binomial test), the share and its interval beside it.

    python benchmarks/crossover_checks.py OUT.json [--seeds 200] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from study.analysis.crossover import ALPHA, design_checks

MEAN_S = 30.0
SHIFT_S = {"outsider": 4.0, "novice": 0.0, "expert": -4.0}
SCENARIOS: dict[str, dict[str, Any]] = {
    "normal": {"groups": {"outsider": 20, "novice": 8, "expert": 8}, "trials": 3, "log": False},
    "lognormal": {"groups": {"outsider": 11, "novice": 5, "expert": 3}, "trials": 2, "log": True},
    "one_trial": {"groups": {"outsider": 20, "novice": 8, "expert": 8}, "trials": 1, "log": False},
}


def draw(scenario: dict[str, Any], seed: int, period: float, carry_over: float) -> list[dict]:
    """One study's trials, tidy (one row per trial)."""
    rng = np.random.default_rng(seed)
    rows = []
    number = 0
    for group, n in scenario["groups"].items():
        for i in range(n):
            number += 1
            order = ("VO", "HV") if i % 2 == 0 else ("HV", "VO")
            person = rng.normal(0.0, 0.25 if scenario["log"] else 3.0)
            for block, condition in enumerate(order, start=1):
                for trial in range(1, scenario["trials"] + 1):
                    base = MEAN_S + SHIFT_S[group] - (2.0 if condition == "HV" else 0.0)
                    if scenario["log"]:
                        time_s = base * np.exp(person + rng.normal(0.0, 0.2))
                        proximal = 0.8 * np.exp(person + rng.normal(0.0, 0.2))
                        distal = 0.3 * np.exp(person + rng.normal(0.0, 0.2))
                    else:
                        time_s = base + person + rng.normal(0.0, 3.0)
                        proximal = abs(rng.normal(0.8, 0.2))
                        distal = abs(rng.normal(0.3, 0.1))
                    time_s += period * MEAN_S if block == 2 else 0.0
                    time_s += carry_over * MEAN_S if (block, condition) == (2, "VO") else 0.0
                    rows.append(
                        {
                            "participant": f"P{number:03d}",
                            "group": group,
                            "task": "lcca",
                            "condition": condition,
                            "block": block,
                            "trial": trial,
                            "completion_time_s": float(time_s),
                            "peak_proximal_force_n": float(proximal),
                            "peak_distal_force_n": float(distal),
                        }
                    )
    return rows


def checked(name: str, seed: int, period: float, carry_over: float) -> tuple[int, list]:
    """One study's number of checks and the (measure, effect) pairs added."""
    result = design_checks(draw(SCENARIOS[name], seed, period, carry_over))
    added = sorted({(c["measure"], c["effect"]) for c in result.checks if c["added"]})
    return len(result.checks), added


def share(k: int, n: int) -> dict:
    """k of n, with its exact (Clopper-Pearson) 95 % interval, and the most a procedure
    whose true rate is `ALPHA` shows at n studies in 95 % of runs (`ceiling`: the 95th
    percentile of Binomial(n, ALPHA), over n): a share above it says the rate is above
    `ALPHA` (a one-sided binomial test at 5 %)."""
    from scipy import stats
    from statsmodels.stats.proportion import proportion_confint

    low, high = proportion_confint(k, n, alpha=0.05, method="beta")
    ceiling = float(stats.binom.ppf(0.95, n, ALPHA)) / n
    return {
        "share": k / n,
        "ci95": [float(low), float(high)],
        "count": k,
        "studies": n,
        "ceiling": ceiling,
    }


def run(name: str, seeds: int, period: float, carry_over: float, start: float, pool) -> dict:
    """The share of `seeds` studies with any term added, and with period and carry-over
    both added to the completion time."""
    any_added = both_added = 0
    checks = 0
    each = {"period": 0, "carry_over": 0}
    futures = [pool.submit(checked, name, seed, period, carry_over) for seed in range(seeds)]
    for seed, future in enumerate(futures):
        checks, pairs = future.result()
        added = {tuple(pair) for pair in pairs}
        any_added += bool(added)
        for effect in each:
            each[effect] += ("completion_time_s", effect) in added
        both_added += {("completion_time_s", "period"), ("completion_time_s", "carry_over")} <= (
            added
        )
        if (seed + 1) % 25 == 0:
            print(
                f"crossover_checks: {name} period {period:g} carry-over {carry_over:g}: "
                f"{seed + 1}/{seeds} studies; {time.monotonic() - start:.0f} s elapsed",
                flush=True,
            )
    return {
        "scenario": name,
        "planted": {"period": period, "carry_over": carry_over},
        "checks_per_study": checks,
        "studies": seeds,
        "share_any_added": any_added / seeds,
        "any_added": share(any_added, seeds),
        "share_period_and_carry_over_added": both_added / seeds,
        "share_added_completion_time": {k: v / seeds for k, v in each.items()},
    }


def carry_over_power(name: str, carry_over: float, rank: int) -> float:
    """The closed-form power of the carry-over's between-participant t test (Grizzle's:
    the participants' mean over their trials, condition orders compared within groups)
    in scenario `name` (normal only), at Holm's level for the `rank`-th smallest p of
    the study's checks: alpha / (checks - rank + 1).

    A participant's mean over their 2 x trials trials has variance sd_p^2 + sd_e^2 /
    (2 trials); the carry-over enters half of the HV-first participants' trials, so its
    estimate is twice the difference of the orders' means, SE = 2 sqrt(var (1/n_AB +
    1/n_BA)), df = participants - 2 x groups (two orders in each group).
    """
    from scipy import stats

    scenario = SCENARIOS[name]
    people = sum(scenario["groups"].values())
    var = 3.0**2 + 3.0**2 / (2 * scenario["trials"])
    se = 2 * np.sqrt(var * (2 / people + 2 / people))
    df = people - 2 * len(scenario["groups"])
    checks = 3 * (3 if scenario["trials"] > 1 else 2)
    alpha = 0.05 / (checks - rank + 1)
    crit = stats.t.ppf(1 - alpha / 2, df)
    nc = carry_over * MEAN_S / se
    return float(stats.nct.sf(crit, df, nc) + stats.nct.cdf(-crit, df, nc))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--seeds", type=int, default=200)
    parser.add_argument("--jobs", type=int, default=1, help="processes (studies in parallel)")
    args = parser.parse_args()
    start = time.monotonic()
    with ProcessPoolExecutor(args.jobs) as pool:
        null = [run(name, args.seeds, 0.0, 0.0, start, pool) for name in SCENARIOS]
        planted = [run(name, args.seeds // 2, 0.1, 0.2, start, pool) for name in SCENARIOS]
    report = {
        "data": "SIMULATED studies drawn by benchmarks/crossover_checks.py",
        "command": " ".join(["python benchmarks/crossover_checks.py", *sys.argv[1:]]),
        "alpha": ALPHA,
        "without_effects": {r["scenario"]: r for r in null},
        "planted": {r["scenario"]: r for r in planted},
        "worst_share_any_added_without_effects": max(r["share_any_added"] for r in null),
        "worst_any_added_without_effects": max(
            (r["any_added"] for r in null), key=lambda a: a["share"]
        ),
        # the period's p comes first in Holm's order, the carry-over second
        "carry_over_power_closed_form": {
            name: carry_over_power(name, 0.2, rank=2) for name in ("normal", "one_trial")
        },
        "took_s": time.monotonic() - start,
    }
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    for r in [*null, *planted]:
        print(
            f"{r['scenario']:<10} planted {r['planted']}: any added {r['share_any_added']:.3f}, "
            f"period and carry-over added {r['share_period_and_carry_over_added']:.3f} "
            f"({r['studies']} studies)"
        )


if __name__ == "__main__":
    main()
