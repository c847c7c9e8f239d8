"""`study bench calibrate`: the calibration loop's targets, measured.

- Per family: a 4-minute, 200 Hz follower recording carrying that one effect at the
  JND's size (RMS 0.192 N over the recording; `delay` at the size its drawn lag makes),
  calibrated from eq. 1: the family named first, the held-out RMSE cut (target: by at
  least a third), and the wall-clock time of the loop (target: <= 60 s).
- The clean recording (target: no effect added) and two effects at once.
- The master: the simulated dial on its calibration lever, from one quadratic.
- The estimator: a recording of the simulated drive itself (`FollowerDrive`, with the
  effects its plant carries beyond eq. 1) calibrated, then the estimator trained twice
  on it, with eq. 1 and with the calibrated physics stage: the validation RMSE of the
  physics stage, of physics + GRU and after the EKF, before and after calibration.

- NOTES (the linear Fig. 8 model of [notes]): clamped static ramps and 1-30 Hz chirps
  of both axes at 1 kHz with 2 % sensor noise; the paper's friction
  hysteresis and counter-clockwise loss should be named on the ramps.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from teleop_core.calibration import FAMILIES, Calibrator, FollowerBase, MasterBase, NotesBase
from teleop_core.calibration.synthetic import JND_N, follower_recording, master_recording
from teleop_core.estimation.extended import ExtendedPhysics
from teleop_core.follower import scenarios
from teleop_core.follower.params import FollowerSensorParams
from teleop_core.follower.plant import FollowerDrive
from teleop_core.follower.sensors import acquire
from teleop_core.notes.params import default_params
from teleop_core.notes.recording import NotesRecording
from teleop_core.notes.simulate import simulate_recording
from teleop_core.progress import Progress, no_progress


@dataclass(frozen=True)
class CalibrateBenchConfig:
    duration_s: float = 240.0
    """Length of each follower recording, s (the target's 4 minutes)."""
    rate_hz: float = 200.0
    """Sampling rate, Hz (the target's 200 Hz)."""
    estimator_duration_s: float = 240.0
    """Length of the drive recording the estimators are trained on, s (at 100 Hz)."""
    epochs: int = 30
    """GRU epochs of each estimator."""
    seed: int = 0

    @classmethod
    def quick(cls) -> CalibrateBenchConfig:
        return cls(duration_s=60.0, rate_hz=100.0, estimator_duration_s=60.0, epochs=2)


def _run(effects: list[str], config: CalibrateBenchConfig, seed: int) -> dict[str, Any]:
    rec, truth = follower_recording(
        config.duration_s, effects, rate_hz=config.rate_hz, seed=seed, size_n=JND_N
    )
    model = FollowerBase()
    start = time.perf_counter()
    cal = Calibrator(model).fit(model.data(rec))
    seconds = time.perf_counter() - start
    report = cal.report()
    return {
        "injected": effects,
        "truth": truth,
        "added": [e["family"] for e in report["effects_added"]],
        "effects_added": report["effects_added"],
        "rmse_before_n": report["rmse_before"],
        "rmse_after_n": report["rmse_after"],
        "cut_fraction": 1.0 - report["rmse_after"] / report["rmse_before"],
        "seconds": seconds,
        "samples": len(rec),
    }


def estimator_before_after(config: CalibrateBenchConfig) -> dict[str, Any]:
    """Calibrate a simulated drive recording and train the estimator with and without it."""
    # lazy: teleop_core.estimation.gru costs 11 ms at start-up
    from teleop_core.estimation.gru import GruConfig

    # lazy: teleop_core.estimation.training costs 32 ms at start-up
    from teleop_core.estimation.training import train_estimator

    rng = np.random.default_rng(config.seed)
    cmd, load = scenarios.teleoperation(config.estimator_duration_s, rng, max_load_n=1.6)
    rec = acquire(FollowerDrive().run(cmd, load), FollowerSensorParams(), rng)
    model = FollowerBase()
    report = Calibrator(model).fit(model.data(rec)).report()
    extension = ExtendedPhysics.from_dict(report, "bench")
    rows = {}
    gru = GruConfig(max_epochs=config.epochs)
    for name, ext in (("eq. 1", None), ("calibrated", extension)):
        _, summary = train_estimator(rec, gru, seed=config.seed, extension=ext)
        rows[name] = summary.validation_rmse_n
    return {
        "samples": len(rec),
        "epochs": config.epochs,
        "effects_added": [e["family"] for e in report["effects_added"]],
        "calibration_rmse_before_n": report["rmse_before"],
        "calibration_rmse_after_n": report["rmse_after"],
        "validation_rmse_n": rows,
    }


def notes_runs(config: CalibrateBenchConfig) -> dict[str, Any]:
    """Calibrate simulated clamped ramp and chirp runs of both NOTES axes."""

    runs = {}
    for dof in ("translation", "rotation"):
        for experiment in ("ramp", "chirp"):
            frame = simulate_recording(
                default_params(dof), experiment, "clamped", noise=0.02, seed=config.seed
            )
            model = NotesBase(dof)
            start = time.perf_counter()
            report = Calibrator(model).fit(model.data(NotesRecording.from_frame(frame))).report()
            runs[f"{dof} {experiment}"] = {
                "added": [e["family"] for e in report["effects_added"]],
                "effects_added": report["effects_added"],
                "rmse_before": report["rmse_before"],
                "rmse_after": report["rmse_after"],
                "seconds": time.perf_counter() - start,
                "samples": len(frame),
            }
    return runs


def run_calibrate_bench(
    config: CalibrateBenchConfig,
    out_dir: Path,
    progress: Progress = no_progress,
    only_open: bool = False,
) -> dict[str, Any]:
    """Run every part, write `calibrate_bench.md` and `calibrate.json` to `out_dir`."""
    # lazy: study.bench.calibrate_open costs 5 ms at start-up
    from study.bench.calibrate_open import markdown as open_markdown

    # lazy: study.bench.calibrate_open costs 5 ms at start-up
    from study.bench.calibrate_open import open_part

    say = progress
    out_dir.mkdir(parents=True, exist_ok=True)
    measured = open_part(config.duration_s, config.rate_hz, config.seed, say)
    if only_open:
        report = {"config": config.__dict__, "open": measured}
        lines = open_markdown(measured, config.duration_s, config.rate_hz)
        (out_dir / "calibrate.json").write_text(json.dumps(report, indent=2) + "\n")
        (out_dir / "calibrate_bench.md").write_text("\n".join(lines) + "\n")
        return report
    families = {}
    for i, family in enumerate(FAMILIES):
        say(f"{family} ({i + 1}/{len(FAMILIES)})")
        families[family] = _run([family], config, config.seed + 100 + i)
    say("clean recording")
    clean = _run([], config, config.seed + 200)
    say("two effects at once")
    pair = _run(["stribeck", "hysteresis"], config, config.seed + 300)
    say("master")
    t, i_ma, f = master_recording(config.duration_s, rate_hz=config.rate_hz, seed=config.seed)
    m = MasterBase()
    master = Calibrator(m).fit(m.data_from_arrays(t, i_ma, f)).report()
    say("NOTES ramps and chirps")
    notes = notes_runs(config)
    say("estimator, with and without the calibration")
    estimator = estimator_before_after(config)
    report = {
        "config": config.__dict__,
        "families": families,
        "clean": clean,
        "two_effects": pair,
        "master": {
            "added": [e["family"] for e in master["effects_added"]],
            "effects_added": master["effects_added"],
            "rmse_before_n": master["rmse_before"],
            "rmse_after_n": master["rmse_after"],
        },
        "estimator": estimator,
        "notes": notes,
        "open": measured,
        "targets_met": {
            "every_family_named_first": all(r["added"][:1] == [f] for f, r in families.items()),
            "every_family_cut_by_a_third": all(
                r["cut_fraction"] >= 1 / 3 for r in families.values()
            ),
            "clean_gets_no_effect": clean["added"] == [],
            "slowest_calibration_s": max(r["seconds"] for r in [*families.values(), clean, pair]),
        },
    }
    (out_dir / "calibrate.json").write_text(json.dumps(report, indent=2) + "\n")
    text = (
        markdown(report)
        + "\n"
        + "\n".join(open_markdown(measured, config.duration_s, config.rate_hz))
        + "\n"
    )
    (out_dir / "calibrate_bench.md").write_text(text)
    return report


def markdown(report: dict[str, Any]) -> str:
    c = report["config"]
    lines = [
        f"# Calibration loop ({c['duration_s']:.0f} s at {c['rate_hz']:.0f} Hz per recording)",
        "",
        "| injected | added (in order) | held-out RMSE before -> after (N) | cut | time (s) |",
        "|---|---|---|---|---|",
    ]
    rows = [*report["families"].values(), report["clean"], report["two_effects"]]
    for r in rows:
        lines.append(
            f"| {' + '.join(r['injected']) or 'none (clean)'} | {', '.join(r['added']) or '-'} "
            f"| {r['rmse_before_n']:.4f} -> {r['rmse_after_n']:.4f} "
            f"| {100 * r['cut_fraction']:.0f} % | {r['seconds']:.1f} |"
        )
    m = report["master"]
    lines += [
        "",
        f"Master (dial on its lever): {', '.join(m['added']) or 'none'}; held-out RMSE "
        f"{m['rmse_before_n']:.4f} -> {m['rmse_after_n']:.4f} N.",
        "",
    ]
    lines += [
        "## NOTES, clamped runs at 1 kHz, 2 % noise",
        "",
        "| run | added (in order) | held-out RMSE before -> after | time (s) |",
        "|---|---|---|---|",
    ]
    for name, r in report["notes"].items():
        lines.append(
            f"| {name} | {', '.join(r['added']) or '-'} | {r['rmse_before']:.4g} -> "
            f"{r['rmse_after']:.4g} | {r['seconds']:.1f} |"
        )
    e = report["estimator"]
    lines += [
        "",
        f"## Estimator on the simulated drive ({e['samples']} samples, {e['epochs']} epochs)",
        "",
        f"Calibration added: {', '.join(e['effects_added']) or 'none'} (held-out RMSE "
        f"{e['calibration_rmse_before_n']:.4f} -> {e['calibration_rmse_after_n']:.4f} N).",
        "",
        "| physics stage | physics (N) | physics + GRU (N) | after EKF (N) |",
        "|---|---|---|---|",
    ]
    for name, v in e["validation_rmse_n"].items():
        lines.append(f"| {name} | {v['physics']:.4f} | {v['hybrid']:.4f} | {v['final']:.4f} |")
    return "\n".join(lines) + "\n"
