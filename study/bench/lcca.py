"""`study bench lcca`: the paper's user study, rehearsed with simulated participants.

The design of [endovascular], IV-D: 20 engineering outsiders, 8 novice doctors, 8 expert
physicians, each navigating into the LCCA under VO and HV (within-subject; the same
simulated person, seed for seed, in both conditions). Reported per group: mean and SD
of completion time, peak proximal force (the estimate the drive renders), peak distal
force and success; HV against VO by the Wilcoxon signed-rank test (scipy), the paired
test the analysis issue uses when differences are not normal. Beside it: HV with a
haptic gain of 0 against VO (the participants must not tell them apart), and each
trial's speed against real time with the whole loop inside.

With `publish_lsl` every trial's samples are also published as a Lab Streaming Layer
stream (`study.lsl.publish`, as `study run --lsl` does), in the session's half-second
steps, inside the timing: the speed then includes the cost of publishing. The session
runner publishes a step as soon as the loop has made it; here the loop runs a trial
whole and its steps are published after it, which costs the same calls.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

from study.protocol.tasks import get_task

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from scipy.stats import wilcoxon

from study.analysis.figures import label_source
from study.protocol.traits import GROUPS, simulated_participant
from study.protocol.trial_run import simulate_trial
from study.tasks.lcca.figures import CONDITION_COLORS, plot_tip_paths
from teleop_core.estimation.estimator import ForceEstimator
from teleop_core.phantom.lcca import LccaPhantom
from teleop_core.progress import Progress, no_progress

MEASURES = ("completion_time_s", "peak_proximal_force_n", "peak_distal_force_n")
LABELS = {
    "completion_time_s": "completion time (s)",
    "peak_proximal_force_n": "peak proximal force (N)",
    "peak_distal_force_n": "peak distal force (N)",
}

SIMULATED_NOTE = (
    "SIMULATED: simulated participants in the simulated LCCA phantom and teleoperation "
    "loop; no measured data"
)
"""Written above every figure of this bench (`figures.label_source`) and in its JSON."""


@dataclass(frozen=True)
class LccaBenchConfig:
    group_sizes: dict[str, int] = field(
        default_factory=lambda: {"outsider": 20, "novice": 8, "expert": 8}
    )
    gain_zero_group: str = "novice"
    max_s: float = 180.0
    seed: int = 0
    publish_lsl: bool = False
    """Publish each trial's samples as an LSL stream, timed with the trial."""

    @classmethod
    def quick(cls) -> LccaBenchConfig:
        return cls(group_sizes={"outsider": 2, "novice": 2, "expert": 2}, max_s=60.0)


def _paired(frame: pd.DataFrame, measure: str, a: str, b: str) -> dict[str, float]:
    wide = frame.pivot(index="participant", columns="condition", values=measure)
    diff = (wide[b] - wide[a]).to_numpy()
    if np.allclose(diff, 0.0) or len(diff) < 2:
        p = 1.0
    else:
        p = float(wilcoxon(wide[b], wide[a]).pvalue)
    return {
        f"mean_{a}": float(wide[a].mean()),
        f"mean_{b}": float(wide[b].mean()),
        "mean_difference": float(diff.mean()),
        "p_wilcoxon": p,
        "n": len(diff),
    }


def _row(summary: dict[str, Any]) -> dict[str, Any]:
    """A trial's row of the bench's table: its keys, measures and counts."""
    keys = ("group", "condition", "success", *MEASURES, "wall_contacts", "attempts")
    return {key: summary[key] for key in (*keys, "obstacles_felt", "obstacles_seen")}


def _group_summaries(
    frame: pd.DataFrame, group_order: list[str]
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Per group and condition the measures' means and SDs, and per group and measure
    the paired VO-HV test."""
    groups: dict[str, Any] = {}
    tests = []
    for group in group_order:
        g = frame[frame["group"] == group]
        groups[group] = {
            condition: {
                **{f"{m}_mean": float(c[m].mean()) for m in MEASURES},
                **{f"{m}_sd": float(c[m].std(ddof=1)) if len(c) > 1 else 0.0 for m in MEASURES},
                "success_rate": float(c["success"].mean()),
                "wall_contacts_mean": float(c["wall_contacts"].mean()),
            }
            for condition, c in g.groupby("condition")
        }
        for measure in MEASURES:
            tests.append({"group": group, "measure": measure, **_paired(g, measure, "VO", "HV")})
    return groups, tests


def _gain_zero(
    config: LccaBenchConfig, estimator: ForceEstimator, phantom: LccaPhantom
) -> dict[str, Any]:
    """VO against HV at haptic gain 0 in `config.gain_zero_group`, paired per measure."""
    zero_rows = []
    for i in range(config.group_sizes.get(config.gain_zero_group, 0)):
        seed = config.seed + 1000 * GROUPS.index(config.gain_zero_group) + i
        traits = simulated_participant(config.gain_zero_group, seed)
        for condition, gain, loop_seed in (("VO", None, seed), ("HV", 0.0, seed + 500)):
            s = simulate_trial(
                get_task("lcca"),
                traits,
                condition,
                loop_seed,
                config.max_s,
                haptic_gain_n_m_per_n=gain,
                estimator=estimator,
                context=phantom,
            ).summary
            zero_rows.append(
                {"participant": i, "condition": condition, **{m: s[m] for m in MEASURES}}
            )
    zero = pd.DataFrame(zero_rows)
    return {m: _paired(zero, m, "VO", "HV") for m in MEASURES} if len(zero) else {}


def run_lcca_bench(
    config: LccaBenchConfig,
    estimator: ForceEstimator,
    out_dir: Path,
    progress: Progress = no_progress,
) -> dict[str, Any]:
    out_dir.mkdir(parents=True, exist_ok=True)
    phantom = LccaPhantom()
    progress("compiling the loop")
    lcca = get_task("lcca")
    expert = simulated_participant("expert", 0)
    # numba compiles here, outside the timing
    simulate_trial(lcca, expert, "HV", 0, 1.0, estimator=estimator, context=phantom)
    publisher = _publisher() if config.publish_lsl else None
    rows: list[dict[str, Any]] = []
    factors: list[float] = []
    paths: list[tuple[Any, str]] = []  # an outsider's trial: its frame and condition
    loop_walls: list[float] = []
    publish_walls: list[float] = []
    total = sum(config.group_sizes.values())
    k = 0
    for group, n in config.group_sizes.items():
        if group not in GROUPS:
            raise ValueError(f"group {group!r}; expected one of {GROUPS}")
        for i in range(n):
            k += 1
            seed = config.seed + 1000 * GROUPS.index(group) + i
            traits = simulated_participant(group, seed)
            progress(f"participant {k}/{total} ({group})")
            for condition in ("VO", "HV"):
                start = time.perf_counter()
                result = simulate_trial(
                    lcca,
                    traits,
                    condition,
                    seed,
                    config.max_s,
                    estimator=estimator,
                    context=phantom,
                )
                wall = time.perf_counter() - start
                loop_walls.append(wall)
                if publisher is not None:
                    publish_walls.append(_publish(publisher, result.frame, condition, len(factors)))
                    wall += publish_walls[-1]
                factors.append(result.summary["completion_time_s"] / wall)
                rows.append({"participant": f"{group}-{i:02d}", **_row(result.summary)})
                if group == "outsider":
                    paths.append((result.frame, condition))
    frame = pd.DataFrame(rows)
    groups, tests = _group_summaries(frame, list(config.group_sizes))
    # HV at zero gain against VO: the participants must not tell them apart
    progress("HV with haptic gain 0")
    gain_zero = _gain_zero(config, estimator, phantom)
    report: dict[str, Any] = {
        "config": asdict(config),
        "groups": groups,
        "tests": tests,
        "gain_zero_vs_vo": gain_zero,
        "speed": {
            "realtime_factor_median": float(np.median(factors)),
            "realtime_factor_min": float(np.min(factors)),
            "trials": len(factors),
        },
    }
    if publisher is not None:
        # paired, within this run: the same trials' loop time with and without publishing
        loop_s, publish_s = float(np.sum(loop_walls)), float(np.sum(publish_walls))
        report["speed"]["lsl_publish"] = {
            "loop_s": loop_s,
            "publish_s": publish_s,
            "share_of_wall_time": publish_s / (loop_s + publish_s),
            "realtime_factor_median_without_publishing": float(
                np.median(
                    np.asarray(factors) * (1 + np.asarray(publish_walls) / np.asarray(loop_walls))
                )
            ),
        }
    frame.to_csv(out_dir / "lcca_trials.csv", index=False)
    fig, axes = plt.subplots(1, 2, figsize=(7.16, 4.2), layout="constrained", sharey=True)
    for ax, condition in zip(axes, ("VO", "HV"), strict=True):
        plot_tip_paths(phantom, [p for p in paths if p[1] == condition], ax)
        ax.set_title(f"all outsiders, {condition}: tip paths, wall contacts", fontsize=8)
    label_source(fig, SIMULATED_NOTE).savefig(out_dir / "lcca_tip_paths.png", dpi=200)
    plt.close(fig)
    fig = plot_groups(frame)
    label_source(fig, SIMULATED_NOTE).savefig(out_dir / "lcca_groups.png", dpi=200)
    plt.close(fig)
    report["data"] = SIMULATED_NOTE
    (out_dir / "lcca_bench.json").write_text(json.dumps(report, indent=2) + "\n")
    (out_dir / "lcca_bench.md").write_text(markdown(report))
    return report


def _publisher() -> Any:
    # lazy: study.lsl.publish costs 10 ms at start-up
    from study.lsl.publish import Publisher

    # lazy: study.protocol.observer costs 3 ms at start-up
    from study.protocol.observer import SessionInfo

    publisher = Publisher()
    publisher.session_started(SessionInfo("lcca bench", "bench", "simulated", "simulated", None))
    return publisher


def _publish(publisher: Any, frame: pd.DataFrame, condition: str, k: int) -> float:
    """Publish one trial's samples in the session runner's steps (`STEP_S`); the wall
    time it took, s (the loop hands the session its rows as arrays: turning the trial's
    frame back into them is not timed)."""
    # lazy: study.protocol.observer costs 3 ms at start-up
    from study.protocol.observer import TrialInfo

    # lazy: study.protocol.session (with sqlalchemy) costs 0.4 s at start-up
    from study.protocol.session import STEP_S

    task = get_task("lcca")
    names = [c.name for c in task.sample_columns]
    rows = frame[names].copy()
    rows["branch"] = rows["branch"].map({r: i for i, r in enumerate(task.regions)})
    rows = rows.to_numpy(dtype=np.float64)
    steps = np.searchsorted(rows[:, 0], np.arange(STEP_S, rows[-1, 0] + STEP_S, STEP_S))
    blocks = np.split(rows, steps)
    start = time.perf_counter()
    info = TrialInfo(k, task, condition, 0, k, False, 1, time.monotonic(), 1.0, False)
    publisher.trial_started(info)
    for block in blocks:
        publisher.samples(info, block)
    publisher.trial_ended(info, "completed", {"completion_time_s": float(rows[-1, 0])})
    return time.perf_counter() - start


def plot_groups(frame: pd.DataFrame) -> plt.Figure:
    """Per group, VO vs HV: mean and SD of each measure."""
    fig, axes = plt.subplots(1, len(MEASURES), figsize=(7.16, 2.4), layout="constrained")
    groups = list(dict.fromkeys(frame["group"]))
    x = np.arange(len(groups))
    for ax, measure in zip(axes, MEASURES, strict=True):
        for j, condition in enumerate(("VO", "HV")):
            c = frame[frame["condition"] == condition].groupby("group")[measure]
            mean, sd = c.mean().reindex(groups), c.std(ddof=1).reindex(groups).fillna(0.0)
            ax.bar(
                x + (j - 0.5) * 0.38,
                mean,
                0.36,
                yerr=sd,
                capsize=2,
                label=condition,
                color=CONDITION_COLORS[condition],
                alpha=0.85,
            )
        ax.set_xticks(x, groups, fontsize=7)
        ax.set_title(LABELS[measure], fontsize=8)
    axes[0].legend(fontsize=7)
    return fig


def markdown(report: dict[str, Any]) -> str:
    lines = [
        "# Simulated LCCA study",
        "",
        "| group | condition | time (s) | peak proximal (N) | peak distal (N) | success |",
        "|---|---|---|---|---|---|",
    ]
    for group, conds in report["groups"].items():
        for condition in ("VO", "HV"):
            r = conds[condition]
            lines.append(
                f"| {group} | {condition} | {r['completion_time_s_mean']:.1f} ± "
                f"{r['completion_time_s_sd']:.1f} | {r['peak_proximal_force_n_mean']:.3f} ± "
                f"{r['peak_proximal_force_n_sd']:.3f} | {r['peak_distal_force_n_mean']:.3f} ± "
                f"{r['peak_distal_force_n_sd']:.3f} | {r['success_rate']:.2f} |"
            )
    lines += ["", "| group | measure | mean VO | mean HV | p (Wilcoxon) |", "|---|---|---|---|---|"]
    for t in report["tests"]:
        lines.append(
            f"| {t['group']} | {t['measure']} | {t['mean_VO']:.3f} | {t['mean_HV']:.3f} "
            f"| {t['p_wilcoxon']:.3g} |"
        )
    lines += ["", "HV at haptic gain 0 vs VO:", ""]
    for m, t in report["gain_zero_vs_vo"].items():
        lines.append(
            f"- {m}: VO {t['mean_VO']:.3f}, HV(0) {t['mean_HV']:.3f}, p = {t['p_wilcoxon']:.3g}"
        )
    sp = report["speed"]
    lines += [
        "",
        f"Speed: median {sp['realtime_factor_median']:.0f}x real time, slowest "
        f"{sp['realtime_factor_min']:.0f}x, over {sp['trials']} trials.",
        "",
    ]
    if "lsl_publish" in sp:
        pub = sp["lsl_publish"]
        lines += [
            f"Publishing the samples as an LSL stream took {100 * pub['share_of_wall_time']:.2f} %"
            f" of the trials' wall time ({pub['publish_s']:.3f} s of "
            f"{pub['loop_s'] + pub['publish_s']:.1f} s); without it the same trials ran at a "
            f"median {pub['realtime_factor_median_without_publishing']:.0f}x real time.",
            "",
        ]
    return "\n".join(lines)
