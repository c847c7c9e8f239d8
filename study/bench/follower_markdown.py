"""follower_bench.md: the follower bench's report (`study.bench.follower`) as Markdown
tables: Tables I-III, Fig. 8's sweep, the costs, and the generalisation part."""

from __future__ import annotations

from typing import Any

from study.bench import generalisation, training_time


def _row(label: object, *values: float) -> str:
    return "| " + " | ".join([str(label), *(f"{v:.4f}" for v in values)]) + " |"


def markdown(report: dict[str, Any]) -> str:
    lines = ["# Follower bench (simulated hardware)", ""]
    if "generalisation" in report:
        lines += generalisation.markdown(report["generalisation"])
    if "table_i" in report:
        lines += _tables_markdown(report)
    if "training_time" in report:
        lines += training_time.markdown(report["training_time"])
    return "\n".join(lines)


def _tables_markdown(report: dict[str, Any]) -> list[str]:
    lines = [
        "## Table I: velocity sensing",
        "",
        "| metric | ramp | step |",
        "|---|---|---|",
    ]
    t1 = report["table_i"]
    for key in (
        "mae_rad_s",
        "rmse_rad_s",
        "max_error_rad_s",
        "tracking_score_pct",
        "command_tracking_score_pct",
    ):
        lines.append(f"| {key} | {t1['ramp'][key]:.4f} | {t1['step'][key]:.4f} |")
    lines.append(f"| steady_state_error_rad_s | - | {t1['step']['steady_state_error_rad_s']:.4f} |")
    lines += [
        "",
        "## Table II: force estimation at zero speed",
        "",
        "| frequency (Hz) | RMSE (N) | MAE (N) | MaxAE (N) | physics-only RMSE (N) |",
        "|---|---|---|---|---|",
    ]
    for f, row in report["table_ii"].items():
        lines.append(
            _row(f, row["rmse_n"], row["mae_n"], row["max_abs_error_n"], row["physics_rmse_n"])
        )
    t3 = report["table_iii"]["pooled"]
    lines += [
        "",
        "## Table III: residual learning vs direct prediction (four held-out cases)",
        "",
        "Both models trained on the same teleoperation recording (bench phantom only).",
        "",
        "| method | RMSE (N) | mean error (N) | std (N) |",
        "|---|---|---|---|",
    ]
    for label, key in (
        ("Residual prediction + F_model", "hybrid"),
        ("  ... after the EKF", "final"),
        ("Direct prediction of F", "direct"),
        ("Physics model alone", "physics"),
        ("Physics + gradient-boosted trees (baseline)", "baseline"),
    ):
        lines.append(_row(label, t3[key]["rmse"], t3[key]["mean_error"], t3[key]["std_error"]))
    lines += [
        "",
        "| case | physics | hybrid | final | direct | baseline |",
        "|---|---|---|---|---|---|",
    ]
    for case, row in report["table_iii"]["cases"].items():
        lines.append(
            _row(case, row["physics"], row["hybrid"], row["final"], row["direct"], row["baseline"])
        )
    lines += [
        "",
        "## Fig. 8: validation RMSE against window length",
        "",
        "| T | RMSE (N) |",
        "|---|---|",
    ]
    lines += [f"| {T} | {v:.4f} |" for T, v in report["window_sweep"].items()]
    tm, tr = report["timing"], report["training"]
    lines += [
        "",
        "## Cost",
        "",
        f"- one causal estimator update: median {tm['median_ms']:.3f} ms, "
        f"p99 {tm['p99_ms']:.3f} ms",
        f"- training on {tr['samples']} samples for {tr['epochs_run']} epochs: "
        f"{tr['seconds']:.0f} s",
        "- validation RMSE (physics / hybrid / final): "
        + " / ".join(f"{v:.4f}" for v in tr["validation_rmse_n"].values())
        + " N",
        "",
    ]
    return lines
