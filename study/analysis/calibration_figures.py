"""Figures of a calibration's held-out residual, before and after the added effects.

One figure per view, each with the base model's residual (grey) and the calibrated
model's (blue): against time, against each of the model's signals (speed and angle for
the follower, current for the master), and the autocorrelation with the white-noise
bounds of the residual tests. The style is the paper figures' (`figures.STYLE`,
Okabe-Ito colours).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from study.analysis.figures import OKABE_ITO, STYLE, WIDTHS_IN, save

COLOURS = {"before": OKABE_ITO["grey"], "after": OKABE_ITO["HV"]}
AXIS_LABELS = {
    "t": "time (s)",
    "speed": "wheel speed (rad/s)",
    "angle": "wheel angle (rad)",
    "drive": "current",
}


def residual_against(
    x: np.ndarray,
    before: np.ndarray,
    after: np.ndarray,
    label: str,
    ax: plt.Axes | None = None,
    unit: str = "N",
) -> plt.Axes:
    """Residuals before and after against `x`; points for signals, lines for time."""
    if ax is None:
        _, ax = plt.subplots(figsize=(WIDTHS_IN["single"], 2.2), layout="constrained")
    as_line = label == AXIS_LABELS["t"]
    if as_line:
        # blocked hold-out: break the line between blocks instead of bridging the gap
        step = np.median(np.diff(x)) if len(x) > 1 else 0.0
        gaps = np.flatnonzero(np.diff(x) > 1.5 * step) + 1
        x, before, after = (
            np.insert(np.asarray(v, float), gaps, np.nan) for v in (x, before, after)
        )
    for name, e in (("before", before), ("after", after)):
        if as_line:
            ax.plot(x, e, color=COLOURS[name], lw=0.5, label=name)
        else:
            ax.scatter(x, e, s=1.0, color=COLOURS[name], alpha=0.5, lw=0, label=name)
    ax.axhline(0.0, color="black", lw=0.4)
    ax.set_xlabel(label)
    ax.set_ylabel(f"residual ({unit})")
    ax.legend(loc="upper right", markerscale=4, frameon=False)
    return ax


def autocorrelation(
    before: dict[str, Any], after: dict[str, Any], ax: plt.Axes | None = None
) -> plt.Axes:
    """Residual autocorrelation before and after, with the +-bound of white noise."""
    if ax is None:
        _, ax = plt.subplots(figsize=(WIDTHS_IN["single"], 2.2), layout="constrained")
    for name, tests, shift in (("before", before, -0.15), ("after", after, 0.15)):
        lags = np.asarray(tests["lags"][1:], float) + shift
        ax.vlines(lags, 0, tests["values"][1:], color=COLOURS[name], lw=1.2, label=name)
    bound = after["bound"]
    ax.axhspan(-bound, bound, color=OKABE_ITO["grey"], alpha=0.2, lw=0, label="99 % bounds")
    ax.axhline(0.0, color="black", lw=0.4)
    ax.set_xlabel("lag (samples)")
    ax.set_ylabel("autocorrelation")
    ax.legend(loc="upper right", frameon=False)
    return ax


def residual_figures(
    out_dir: Path,
    signals: dict[str, np.ndarray],
    before: np.ndarray,
    after: np.ndarray,
    tests_before: dict[str, Any],
    tests_after: dict[str, Any],
    against: Sequence[str],
    drive_label: str = "current",
    unit: str = "N",
) -> list[Path]:
    """Write `residual_vs_<signal>.png` for each of `against` and `residual_acf.png`."""
    labels = {**AXIS_LABELS, "drive": drive_label}
    paths: list[Path] = []
    with plt.rc_context(STYLE):
        for key in against:
            ax = residual_against(signals[key], before, after, labels[key], unit=unit)
            paths += save(ax.figure, out_dir, f"residual_vs_{key}", ["png"])
        ax = autocorrelation(tests_before["autocorrelation"], tests_after["autocorrelation"])
        paths += save(ax.figure, out_dir, "residual_acf", ["png"])
    return paths
