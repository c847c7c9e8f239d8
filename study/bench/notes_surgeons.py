"""The surgeons' benchmark of [notes] (IV, [20]) on simulated experts: part of
`study bench notes`.

[notes] reports, over 10 surgeons in porcine NOTES procedures, the mean of each
surgeon's maximum pull and push, the mean maximum clockwise and counter-clockwise
torque, and the share of the procedure's time the push exceeded the device's 5.62 N.
Here `n` simulated experts (the paper's 10 by default) each do one NOTES trial in VO
(nothing rendered: the tissue's demand is what a hand on a real scope would feel), and
the same people in HV beside them; each trial's measures are the task's own
(`study.tasks.notes.trial.measures`). The table puts the paper's figure, the target
band of the participant fit, and the simulated people's mean, SD, min and max side by side; every
table and key says the trials are simulated.
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from teleop_core.notes import task
from teleop_core.progress import Progress, no_progress

SOURCE = "simulated participants (study.tasks.notes.trial), not measured people"
PAPER = {
    "peak_push_n": (task.PUSH_BENCHMARK_N, 1.0, "N", 1.0),
    "peak_pull_n": (task.PULL_BENCHMARK_N, 0.7, "N", 1.0),
    "peak_torque_cw_n_m": (task.CW_BENCHMARK_N_M, 0.010, "N mm", 1e3),
    "peak_torque_ccw_n_m": (task.CCW_BENCHMARK_N_M, 0.010, "N mm", 1e3),
    "push_over_capacity_fraction": (task.PUSH_OVER_LIMIT_BENCHMARK, 0.04, "%", 100.0),
}
"""Measure -> (the surgeons' mean, the target's half-width, display unit, SI -> display)."""
GROUP = "expert"
CONDITION = "VO"


def surgeons_summary(trials: pd.DataFrame) -> pd.DataFrame:
    """The paper beside the simulated people: one row per measure of `PAPER`.

    Parameters
    ----------
    trials
        One row per simulated person, a column per measure of `PAPER` in SI units.

    Returns
    -------
    DataFrame with columns measure, paper, target_low, target_high, mean, sd, min, max,
    n, within_target (SI units; sd with ddof = 1).
    """
    rows = []
    for measure, (paper, half, _, _) in PAPER.items():
        values = trials[measure].astype(float)
        mean = float(values.mean())
        rows.append(
            {
                "measure": measure,
                "paper": paper,
                "target_low": paper - half,
                "target_high": paper + half,
                "mean": mean,
                "sd": float(values.std(ddof=1)) if len(values) > 1 else float("nan"),
                "min": float(values.min()),
                "max": float(values.max()),
                "n": len(values),
                "within_target": bool(abs(mean - paper) <= half),
            }
        )
    return pd.DataFrame(rows)


def surgeons_trials(n: int, seed: int, progress: Progress = no_progress) -> pd.DataFrame:
    """One NOTES trial per simulated expert in VO and in HV (the same person, seed for
    seed); one row per trial with the measures of `PAPER`, completion and success."""
    from study.protocol.design import MAX_TRIAL_S
    from study.protocol.tasks import get_task

    # lazy: study.protocol.traits costs about 20 ms at start-up
    from study.protocol.traits import simulated_participant
    from study.protocol.trial_run import simulate_trial

    notes = get_task("notes")

    rows = []
    for k in range(n):
        person = seed * 1000 + k
        traits = simulated_participant(GROUP, person)
        for condition in (CONDITION, "HV"):
            progress(f"surgeons' benchmark: simulated expert {k + 1}/{n}, {condition}")
            s = simulate_trial(notes, traits, condition, person, MAX_TRIAL_S).summary
            rows.append(
                {
                    "participant": k,
                    "seed": person,
                    "condition": condition,
                    "success": bool(s["success"]),
                    "completion_time_s": float(s["completion_time_s"]),
                    **{m: float(s[m]) for m in PAPER},
                }
            )
    return pd.DataFrame(rows)


def surgeons_report(trials: pd.DataFrame) -> tuple[dict[str, Any], list[str]]:
    """(the JSON part, the Markdown lines) of the benchmark from `surgeons_trials`."""
    summaries = {c: surgeons_summary(trials[trials["condition"] == c]) for c in (CONDITION, "HV")}
    vo = summaries[CONDITION]
    report = {
        "source": SOURCE,
        "group": GROUP,
        "condition": CONDITION,
        "participants": trials.to_dict(orient="records"),
        "summary": vo.to_dict(orient="records"),
        "summary_hv": summaries["HV"].to_dict(orient="records"),
        "all_within_target": bool(vo["within_target"].all()),
    }
    n = int(vo["n"].iloc[0])
    md = [
        "",
        f"Surgeons' benchmark ([notes], IV: 10 surgeons, porcine NOTES) against {n} "
        f"SIMULATED experts in {CONDITION}, one trial each (HV: the same people):",
        "",
        "| measure | paper | target | simulated VO mean | SD | min-max | within | "
        "simulated HV mean |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (_, r), (_, h) in zip(vo.iterrows(), summaries["HV"].iterrows(), strict=True):
        _, half, unit, k = PAPER[r["measure"]]
        md.append(
            f"| {r['measure']} ({unit}) | {r['paper'] * k:.4g} | {r['paper'] * k:.4g} "
            f"+/- {half * k:.3g} | {r['mean'] * k:.2f} | {r['sd'] * k:.2f} "
            f"| {r['min'] * k:.2f}-{r['max'] * k:.2f} | {'yes' if r['within_target'] else 'NO'} "
            f"| {h['mean'] * k:.2f} |"
        )
    md += ["", f"Per simulated expert ({CONDITION}):", ""]
    columns = ["participant", "completion_time_s", *(f"{m} ({PAPER[m][2]})" for m in PAPER)]
    md.append("| " + " | ".join(columns) + " |")
    md.append("|" + "---|" * len(columns))
    for _, r in trials[trials["condition"] == CONDITION].iterrows():
        cells = [f"{int(r['participant'])}", f"{r['completion_time_s']:.1f}"]
        cells += [f"{r[m] * PAPER[m][3]:.2f}" for m in PAPER]
        md.append("| " + " | ".join(cells) + " |")
    return report, md
