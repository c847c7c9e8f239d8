"""`study bench follower --only training`: the time `study estimator train` takes on the
paper's dataset size (target: 60,000 samples in at most 600 s here).

Two runs on the bench's training recording (`follower.training_recording`, 60,000
samples at 100 Hz by default), both with the command's defaults (the effect search, the
memory features, the paper's Adam settings):
- `default`: early stopping as the command does it (`GruConfig.patience`);
- `all_epochs`: no early stopping, every one of `--epochs` epochs (100), the worst case
  the command can take with its default epoch count.
Each gives the whole call's wall time, the time before the first epoch (the effect search,
the physics fit, the windows) and the per-epoch times; the load average before and after
says how busy the machine was.
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from teleop_core.estimation.gru import GruConfig
from teleop_core.estimation.training import train_estimator
from teleop_core.follower.recording import FollowerRecording
from teleop_core.progress import Progress

TARGET_S = 600.0
"""Target: training 60,000 samples stays within 600 s on this machine."""


def _timed_training(
    recording: FollowerRecording,
    gru_config: GruConfig,
    seed: int,
    name: str,
    progress: Progress,
) -> dict[str, Any]:
    stamps: list[float] = []

    def on_epoch(step: str, done: int = 0, total: int = 0) -> None:
        if done:  # an epoch ended (the effect search before the GRU reports no count)
            stamps.append(time.perf_counter())
        progress(f"training time ({name}): {step}", done, total)

    load_before = os.getloadavg()
    start = time.perf_counter()
    _, summary = train_estimator(recording, gru_config, seed=seed, progress=on_epoch, effects=True)
    seconds = time.perf_counter() - start
    epochs = np.diff([start, *stamps])
    return {
        "samples": len(recording),
        "max_epochs": gru_config.max_epochs,
        "patience": gru_config.patience,
        "epochs_run": summary.epochs_run,
        "best_epoch": summary.best_epoch,
        "seconds": seconds,
        "seconds_to_first_epoch_end": float(epochs[0]) if len(epochs) else seconds,
        "per_epoch_s": {
            "median": float(np.median(epochs[1:])) if len(epochs) > 1 else float("nan"),
            "min": float(np.min(epochs[1:])) if len(epochs) > 1 else float("nan"),
            "max": float(np.max(epochs[1:])) if len(epochs) > 1 else float("nan"),
        },
        "after_last_epoch_s": seconds - (stamps[-1] - start) if stamps else 0.0,
        "validation_rmse_n": summary.validation_rmse_n,
        "load_before": list(load_before),
        "load_after": list(os.getloadavg()),
        "within_target": seconds <= TARGET_S,
    }


def run_training_time(
    recording: FollowerRecording, epochs: int, seed: int, progress: Progress
) -> dict[str, Any]:
    """Both runs on `recording` (module docstring); the report's `training_time` entry."""
    every = GruConfig(max_epochs=epochs, patience=None)
    runs = {
        "default": _timed_training(
            recording, GruConfig(max_epochs=epochs), seed, "default", progress
        ),
        "all_epochs": _timed_training(recording, every, seed, "all epochs", progress),
    }
    return {
        "target_s": TARGET_S,
        "data": "simulated recording (bench phantom + calibration platform)",
        "runs": runs,
        "within_target": all(r["within_target"] for r in runs.values()),
    }


def markdown(report: dict[str, Any]) -> list[str]:
    lines = [
        "## Training time (`study estimator train` defaults)",
        "",
        f"Target: at most {report['target_s']:.0f} s; {report['data']}.",
        "",
        "| run | samples | epochs (best) | wall (s) | before the 1st epoch ends (s) "
        "| per epoch, median (min-max) (s) | load before -> after |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in report["runs"].items():
        e = r["per_epoch_s"]
        lines.append(
            f"| {name} | {r['samples']} | {r['epochs_run']} ({r['best_epoch']}) "
            f"| {r['seconds']:.0f} | {r['seconds_to_first_epoch_end']:.1f} "
            f"| {e['median']:.2f} ({e['min']:.2f}-{e['max']:.2f}) "
            f"| {r['load_before'][0]:.1f} -> {r['load_after'][0]:.1f} |"
        )
    return [*lines, ""]
