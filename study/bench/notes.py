"""`study bench notes`: the NOTES device's targets ([notes]) measured on the simulation.

- Default parameters: force bandwidth and settling time of the linear model and as
  characterised (ramps and chirps with friction on), continuous limits from the ramps.
- Identification round trip: `draws` seeded draws of the five Fig. 8 parameters, each
  moved by up to +/-30 % from its default, simulated open and clamped chirps with 2 %
  sensor noise, grey-box fit from the defaults; the largest relative error of any
  parameter per draw (target: every parameter within 5 %).
- NOTES trials: `trials` per group and condition, the paper's measures.
- The surgeons' benchmark (`notes_surgeons`): `surgeons` simulated experts in VO
  against the 10 surgeons' mean max pull / push, CW / CCW torque and time above
  5.62 N, with the spread across the simulated people.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from study.bench.notes_surgeons import surgeons_report, surgeons_trials
from teleop_core.notes.characterize import characterize_simulated
from teleop_core.notes.identify import GreyBoxFit, measure_frf
from teleop_core.notes.params import DOFS, MSD_FIELDS, default_params
from teleop_core.notes.recording import NotesRecording
from teleop_core.notes.simulate import BOUNDARIES, simulate_recording
from teleop_core.notes.transfer import force_bandwidth_hz, settling_time_s
from teleop_core.progress import Progress, no_progress

PAPER = {"translation": (18.1, 5.62), "rotation": (5.7, 0.19005)}
"""Force bandwidth (Hz) and continuous limit (N, N m) the paper reports."""


@dataclass(frozen=True)
class NotesBenchConfig:
    draws: int = 10
    """Seeded parameter draws per axis for the round trip."""
    spread: float = 0.30
    noise: float = 0.02
    seed: int = 0
    trials: int = 4
    """NOTES trials per group and condition."""
    surgeons: int = 10
    """Simulated experts for the surgeons' benchmark (the paper had 10 surgeons)."""


def round_trip(dof: str, draw: int, config: NotesBenchConfig) -> dict[str, Any]:
    """One seeded identification round trip; the relative error of each parameter."""
    base = default_params(dof)
    rng = np.random.default_rng([config.seed, draw, DOFS.index(dof)])
    factors = {n: float(rng.uniform(1 - config.spread, 1 + config.spread)) for n in MSD_FIELDS}
    truth = base.linear.scaled(factors)
    device = base.with_linear(truth)
    frfs = [
        measure_frf(
            NotesRecording.from_frame(
                simulate_recording(
                    device, "chirp", b, nonlinear=False, noise=config.noise, seed=draw * 2 + i
                )
            )
        )
        for i, b in enumerate(BOUNDARIES)
    ]
    fit = GreyBoxFit(base.linear).fit(frfs)
    err = np.array(fit.params_.as_tuple()) / np.array(truth.as_tuple()) - 1
    return {
        "dof": dof,
        "draw": draw,
        **{f"err_{n}": float(e) for n, e in zip(MSD_FIELDS, err, strict=True)},
        "max_abs_err": float(np.max(np.abs(err))),
    }


TRIAL_MEASURES = (
    "success",
    "completion_time_s",
    "peak_force_demanded_n",
    "peak_force_rendered_n",
    "peak_torque_demanded_n_m",
    "peak_torque_rendered_n_m",
    "peak_push_n",
    "peak_pull_n",
    "push_over_capacity_fraction",
)


def notes_trials(config: NotesBenchConfig, progress: Progress) -> tuple[pd.DataFrame, float]:
    """`trials` simulated NOTES trials per group and condition; (measures, wall seconds)."""
    # lazy: study.protocol.design costs 18 ms at start-up
    from study.protocol.design import KNOWN_CONDITIONS as CONDITIONS
    from study.protocol.design import MAX_TRIAL_S
    from study.protocol.tasks import get_task

    # lazy: study.protocol.traits costs about 20 ms at start-up
    from study.protocol.traits import GROUPS, simulated_participant
    from study.protocol.trial_run import simulate_trial

    notes = get_task("notes")

    rows = []
    t0 = time.perf_counter()
    for group in GROUPS:
        for k in range(config.trials):
            traits = simulated_participant(group, config.seed * 1000 + k)
            for condition in CONDITIONS:
                progress(f"NOTES trial {group} {condition} {k + 1}/{config.trials}")
                s = simulate_trial(
                    notes, traits, condition, config.seed * 1000 + k, MAX_TRIAL_S
                ).summary
                rows.append(
                    {
                        "group": group,
                        "condition": condition,
                        "participant": k,
                        **{m: float(s[m]) for m in TRIAL_MEASURES},
                    }
                )
    return pd.DataFrame(rows), time.perf_counter() - t0


def run_notes_bench(
    config: NotesBenchConfig, out_dir: Path, progress: Progress = no_progress
) -> dict[str, Any]:
    out_dir.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {"config": config.__dict__}
    rows = []
    for dof in DOFS:
        progress(f"characterising {dof}")
        p = default_params(dof)
        ch = characterize_simulated(p)
        bw_paper, limit_paper = PAPER[dof]
        rows.append(
            {
                "dof": dof,
                "bandwidth_linear_hz": force_bandwidth_hz(p.linear),
                "bandwidth_characterised_hz": ch.bandwidth_hz,
                "bandwidth_paper_hz": bw_paper,
                "settling_linear_s": settling_time_s(p.linear),
                "settling_characterised_s": ch.settling_time_s,
                "max_continuous": ch.before.max_continuous,
                "max_continuous_paper": limit_paper,
            }
        )
    report["defaults"] = rows
    trips = []
    t0 = time.perf_counter()
    for dof in DOFS:
        for draw in range(config.draws):
            progress(f"round trip {dof} {draw + 1}/{config.draws}")
            trips.append(round_trip(dof, draw, config))
    frame = pd.DataFrame(trips)
    report["round_trip"] = trips
    report["round_trip_summary"] = {
        dof: {
            "draws": int((frame.dof == dof).sum()),
            "worst_abs_err": float(frame.loc[frame.dof == dof, "max_abs_err"].max()),
            "within_5_percent": int((frame.loc[frame.dof == dof, "max_abs_err"] < 0.05).sum()),
        }
        for dof in DOFS
    }
    report["round_trip_seconds"] = time.perf_counter() - t0
    md = [
        "| dof | bandwidth linear (Hz) | as characterised (Hz) | paper (Hz) | settling linear (s) "
        "| as characterised (s) | max continuous | paper |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        md.append(
            f"| {r['dof']} | {r['bandwidth_linear_hz']:.2f} "
            f"| {r['bandwidth_characterised_hz']:.2f} "
            f"| {r['bandwidth_paper_hz']} | {r['settling_linear_s']:.3f} "
            f"| {r['settling_characterised_s']:.3f} | {r['max_continuous']:.5g} "
            f"| {r['max_continuous_paper']} |"
        )
    md += ["", "| dof | draws | within 5 % | worst parameter error |", "|---|---|---|---|"]
    for dof, s in report["round_trip_summary"].items():
        md.append(f"| {dof} | {s['draws']} | {s['within_5_percent']} | {s['worst_abs_err']:.2%} |")
    trials, wall = notes_trials(config, progress)
    report["notes_trials"] = trials.to_dict(orient="records")
    simulated = float(trials["completion_time_s"].sum())
    report["notes_trials_real_time_factor"] = simulated / wall
    means = trials.groupby(["group", "condition"], sort=False)[list(TRIAL_MEASURES)].mean()
    md += [
        "",
        f"SIMULATED NOTES trials ({config.trials} per group and condition; "
        f"{simulated / wall:.0f}x real time):",
        "",
        "| group | condition | " + " | ".join(TRIAL_MEASURES) + " |",
        "|---|---|" + "---|" * len(TRIAL_MEASURES),
    ]
    for (group, condition), row in means.iterrows():
        md.append(f"| {group} | {condition} | " + " | ".join(f"{v:.3g}" for v in row) + " |")
    surgeons = surgeons_trials(config.surgeons, config.seed, progress)
    report["surgeons_benchmark"], lines = surgeons_report(surgeons)
    md += lines
    surgeons.to_csv(out_dir / "notes_surgeons.csv", index=False)
    (out_dir / "notes_bench.md").write_text("\n".join(md) + "\n")
    frame.to_csv(out_dir / "notes_round_trip.csv", index=False)
    return report
