"""Figures of a calibration's residual, before and after the added effects.

One figure per view, each with the base model's residual (grey) and the calibrated
model's (blue): against time, against each of the model's signals (speed and angle for
the follower, current for the master), and the autocorrelation with the white-noise
bounds of the residual tests, all on the held-out block. Two more:

- `residual_blocks`: the residual over the whole recording, before and after, with the
  training and held-out blocks shaded and labelled, so that what the fit saw and what
  it is judged on are told apart at a glance;
- `residual_vs_unexplained` (verdict `structure_remains` only): the held-out residual
  against the quantity that REPORT.json's `unexplained` names, with its binned
  conditional means (the bins of the report), on the quantity as the verdict binned it.

The style is the paper figures' (`figures.STYLE`, Okabe-Ito colours) with text at
8 pt or more, since these figures are read on their own rather than in a column.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib.pyplot as plt
import numpy as np

from study.analysis.figures import OKABE_ITO, STYLE, WIDTHS_IN, figure_of, save
from teleop_core.calibration.verdict import SHARE_STRUCTURE

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

COLOURS = {"before": OKABE_ITO["grey"], "after": OKABE_ITO["HV"]}
AXIS_LABELS = {
    "t": "time (s)",
    "speed": "wheel speed (rad/s)",
    "angle": "wheel angle (rad)",
    "drive": "current",
}
CAL_STYLE: dict[RcKeyType, Any] = {
    **STYLE,
    "font.size": 8,
    "axes.titlesize": 8,
    "axes.labelsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 8,
}
"""`STYLE` with every text at 8 pt."""
SIGNAL_LABELS: dict[str, dict[str, str]] = {
    "follower": {
        "drive": "q-axis current (A)",
        "speed": "wheel speed (rad/s)",
        "accel": "wheel acceleration (rad/s$^2$)",
        "angle": "wheel angle (rad)",
    },
    "master": {"drive": "current (mA)"},
    "notes-translation": {"drive": "commanded force (N)", "linear": "linear model's force (N)"},
    "notes-rotation": {"drive": "commanded torque (N m)", "linear": "linear model's torque (N m)"},
    "rigid-axis": {
        "speed": "velocity q' (m/s or rad/s)",
        "accel": "acceleration q'' (m/s$^2$ or rad/s$^2$)",
        "angle": "position q (m or rad)",
    },
}
"""Axis labels, with units, of each base model's signals (its recording contract)."""


def signal_labels(model: str, position_unit: str | None = None) -> dict[str, str]:
    """Axis labels, with units, of `model`'s signals; for the rigid axis in the unit of
    its position (`position_unit`: "m" for a linear axis, "rad" for a rotary one; None:
    either).

    >>> signal_labels("rigid-axis", "m")["angle"]
    'position q (m)'
    """
    if model != "rigid-axis" or position_unit is None:
        return SIGNAL_LABELS.get(model, {})
    u = position_unit
    return {
        "speed": f"velocity q' ({u}/s)",
        "accel": f"acceleration q'' ({u}/s$^2$)",
        "angle": f"position q ({u})",
    }


def quantity_label(name: str, model: str, unit: str = "N", position_unit: str | None = None) -> str:
    """Axis label with units for a channel or derived quantity of `verdict.quantities`.

    >>> quantity_label("speed band", "follower")
    '|wheel speed| (rad/s)'
    """
    signals = signal_labels(model, position_unit)
    if name == "time window":
        return "time (s)"
    if name == "load":
        return f"load: |predicted output| ({unit})"
    if name == "direction":
        return "direction of motion (sign of speed)"
    if name == "speed band":
        label = signals.get("speed", "speed")
        word, _, rest = label.partition(" (")
        return f"|{word}| ({rest}" if rest else f"|{word}|"
    if name == "distance since reversal":
        rest = signals.get("angle", "position").partition(" (")[2]
        return (
            f"distance since the last reversal ({rest}"
            if rest
            else ("distance since the last reversal")
        )
    return signals.get(name, f"{name} (recorded units)")


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
    labels: dict[str, str] | None = None,
) -> list[Path]:
    """Write `residual_vs_<signal>.png` for each of `against` and `residual_acf.png`;
    `labels`: the model's signal labels (`signal_labels`) over the follower's."""
    labels = {**AXIS_LABELS, "drive": drive_label, **(labels or {})}
    paths: list[Path] = []
    with plt.rc_context(CAL_STYLE):
        for key in against:
            ax = residual_against(signals[key], before, after, labels[key], unit=unit)
            paths += save(figure_of(ax), out_dir, f"residual_vs_{key}", ["png"])
        ax = autocorrelation(tests_before["autocorrelation"], tests_after["autocorrelation"])
        paths += save(figure_of(ax), out_dir, "residual_acf", ["png"])
    return paths


def held_out_mask(n: int, held_out: slice | np.ndarray) -> np.ndarray:
    """Boolean mask of the held-out rows (the loop's `test_`: a slice or indices)."""
    mask = np.zeros(n, dtype=bool)
    mask[held_out] = True
    return mask


def _runs(mask: np.ndarray) -> list[tuple[int, int, bool]]:
    """(start, stop, value) of the runs of equal values in a boolean mask."""
    edges = np.flatnonzero(np.diff(mask.astype(np.int8))) + 1
    starts = np.r_[0, edges]
    stops = np.r_[edges, len(mask)]
    return [(int(a), int(b), bool(mask[a])) for a, b in zip(starts, stops, strict=True)]


def residual_blocks(
    t: np.ndarray,
    before: np.ndarray,
    after: np.ndarray,
    held_out: np.ndarray,
    unit: str = "N",
    axes: Sequence[plt.Axes] | None = None,
) -> np.ndarray:
    """The residual over the whole recording, before (top) and after (bottom) the added
    effects, with the training and held-out blocks shaded and labelled.

    Parameters
    ----------
    t
        Time, s, shape (n,).
    before, after
        Residual of the base model and of the calibrated one, `unit`, shape (n,).
    held_out
        Boolean mask of the held-out rows, shape (n,).

    Returns
    -------
    The two Axes.
    """
    if axes is None:
        _, axes = plt.subplots(
            2, 1, figsize=(WIDTHS_IN["double"], 3.6), sharex=True, sharey=True, layout="constrained"
        )
    runs = _runs(np.asarray(held_out, bool))
    rmse = {}
    for ax, name, e in zip(axes, ("before", "after"), (before, after), strict=True):
        for start, stop, is_held in runs:
            x0, x1 = t[start], t[stop - 1]
            if is_held:
                ax.axvspan(x0, x1, color=OKABE_ITO["VO"], alpha=0.12, lw=0)
        ax.plot(t, e, color=COLOURS[name], lw=0.4)
        ax.axhline(0.0, color="black", lw=0.4)
        rmse[name] = (
            float(np.sqrt(np.mean(e[~held_out] ** 2))),
            float(np.sqrt(np.mean(e[held_out] ** 2))),
        )
        what = "base model" if name == "before" else "calibrated model"
        ax.set_title(
            f"{name}: {what}; RMSE training {rmse[name][0]:.4g} {unit}, "
            f"held out {rmse[name][1]:.4g} {unit}",
            loc="left",
        )
        ax.set_ylabel(f"residual ({unit})")
    axes[-1].set_xlabel("time (s)")
    top = axes[0]
    # block labels in the top panel's upper margin: axis fraction in y, data in x
    trans = top.get_xaxis_transform()
    labelled = [r for r in runs if r[1] - r[0] > 0.04 * len(t)]
    # a few blocks are named in place; many (a NOTES chirp's 8) by a legend above
    for start, stop, is_held in labelled if len(labelled) <= 4 else []:
        middle = 0.5 * (t[start] + t[stop - 1])
        top.text(
            middle,
            0.97,
            "held out" if is_held else "training",
            transform=trans,
            ha="center",
            va="top",
            color=OKABE_ITO["VO"] if is_held else "black",
            bbox={"facecolor": "white", "alpha": 0.8, "lw": 0, "pad": 1.0},
        )
    if len(labelled) > 4:
        from matplotlib.patches import Patch

        top.legend(
            handles=[
                Patch(color=OKABE_ITO["VO"], alpha=0.12, label="held out"),
                Patch(facecolor="white", edgecolor="black", lw=0.4, label="training"),
            ],
            loc="lower right",
            bbox_to_anchor=(1.0, 1.0),
            frameon=False,
            ncols=2,
            borderaxespad=0.2,
        )
    return np.asarray(axes)


def residual_against_unexplained(
    x: np.ndarray,
    residual: np.ndarray,
    where: dict[str, Any],
    label: str,
    unit: str = "N",
    ax: plt.Axes | None = None,
) -> plt.Axes:
    """The held-out residual against the quantity `where` (REPORT.json's `unexplained`)
    names, with its binned conditional means.

    Parameters
    ----------
    x
        The quantity as the verdict binned it (`verdict.quantities`), shape (n,).
    residual
        The calibrated model's held-out residual, `unit`, shape (n,).
    where
        The report's `unexplained` entry: `quantity`, `bins` ({`low`, `high`, `n`,
        `mean_residual`}), `share_of_variance`, `share_beyond_chance`.
    label
        x-axis label with units (`quantity_label`).
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(WIDTHS_IN["single"] + 0.5, 2.8), layout="constrained")
    ax.scatter(
        x,
        residual,
        s=1.5,
        color=COLOURS["after"],
        alpha=0.35,
        lw=0,
        label="held-out residual",
        rasterized=True,
    )
    bins = where.get("bins") or []
    if bins:
        low = np.array([b["low"] for b in bins])
        high = np.array([b["high"] for b in bins])
        mean = np.array([b["mean_residual"] for b in bins])
        ax.hlines(mean, low, high, color="black", lw=1.4, label="bin mean")
        ax.plot(0.5 * (low + high), mean, "o", color="black", ms=2.5)
    ax.axhline(0.0, color=OKABE_ITO["grey"], lw=0.5)
    ax.set_xlabel(label)
    ax.set_ylabel(f"residual ({unit})")
    # the scale of the bulk of the points, so that the bin means stay readable under
    # a few spikes (EMPS's reversals); how many points lie beyond it is said
    e = np.asarray(residual, float)
    low, high = np.percentile(e, [0.5, 99.5])
    pad = 0.15 * (high - low)
    beyond = int(np.sum((e < low - pad) | (e > high + pad)))
    ax.set_ylim(low - pad, high + pad)
    if beyond:
        ax.text(
            0.01,
            0.02,
            f"{beyond} points beyond the axis",
            transform=ax.transAxes,
            ha="left",
            va="bottom",
            color=OKABE_ITO["grey"],
        )
    share, excess = 100 * where["share_of_variance"], 100 * where["share_beyond_chance"]
    title = f"bin means explain {share:.1f} % ({excess:.1f} % beyond chance)"
    if where["share_beyond_chance"] < SHARE_STRUCTURE:
        # the verdict rests on the residual's smoothness in time, not on this quantity
        dw = where.get("durbin_watson")
        why = (
            f"structure in time (Durbin-Watson {dw:.2f})"
            if dw is not None
            else ("no quantity explains it")
        )
        title += f"\nbelow {100 * SHARE_STRUCTURE:.0f} %: {why}"
    ax.set_title(title, loc="left")
    ax.legend(loc="upper right", markerscale=4, frameon=False)
    return ax


def overview_figures(
    out_dir: Path,
    t: np.ndarray,
    before: np.ndarray,
    after: np.ndarray,
    held_out: np.ndarray,
    report: dict[str, Any],
    unexplained_x: np.ndarray | None,
    model: str,
    unit: str = "N",
    position_unit: str | None = None,
) -> list[Path]:
    """Write `residual_blocks.png`, and with verdict `structure_remains` also
    `residual_vs_unexplained.png` (`unexplained_x`: the named quantity over the
    held-out rows; `position_unit`: the rigid axis's, `signal_labels`)."""
    paths: list[Path] = []
    with plt.rc_context(CAL_STYLE):
        axes = residual_blocks(t, before, after, held_out, unit)
        paths += save(figure_of(axes[0]), out_dir, "residual_blocks", ["png"])
        where = report.get("unexplained")
        if report.get("verdict") == "structure_remains" and where and unexplained_x is not None:
            label = quantity_label(where["quantity"], model, unit, position_unit)
            ax = residual_against_unexplained(unexplained_x, after[held_out], where, label, unit)
            paths += save(figure_of(ax), out_dir, "residual_vs_unexplained", ["png"])
    return paths


def validation_panel(validation: Any, unit: str = "N", ax: plt.Axes | None = None) -> plt.Axes:
    """One validation recording (`teleop_core.calibration.validation.Validation`): its
    measured output and the base and calibrated models' predictions over all its
    samples, as MATLAB's `compare` draws them, the RMSEs and the fit in the title."""
    if ax is None:
        _, ax = plt.subplots(figsize=(WIDTHS_IN["double"], 2.0), layout="constrained")
    v = validation
    ax.plot(v.t, v.measured, color="black", lw=1.0, label="measured")
    ax.plot(v.t, v.base, color=COLOURS["before"], lw=0.6, label="base model")
    ax.plot(v.t, v.final, color=COLOURS["after"], lw=0.6, label="calibrated model")
    ax.set_title(
        f"{Path(v.recording).name}: RMSE base {v.rmse_base:.4g} {unit} -> calibrated "
        f"{v.rmse_final:.4g} {unit}; fit {v.fit_percent:.1f} % ({v.samples} samples)",
        loc="left",
    )
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"output ({unit})")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)
    return ax


def validation_figure(out_dir: Path, validations: Sequence[Any], unit: str = "N") -> list[Path]:
    """Write `validation.png`: a `validation_panel` per validation recording, stacked,
    for a model calibrated on another recording; nothing when there are none."""
    if not validations:
        return []
    with plt.rc_context(CAL_STYLE):
        fig, axes = plt.subplots(
            len(validations),
            1,
            figsize=(WIDTHS_IN["double"], 2.0 * len(validations) + 0.3),
            layout="constrained",
            squeeze=False,
        )
        for v, ax in zip(validations, axes[:, 0], strict=True):
            validation_panel(v, unit, ax)
        return save(fig, out_dir, "validation", ["png"])
