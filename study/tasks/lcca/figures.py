"""Figures of LCCA trials: forces over time, and tip paths drawn on the phantom; `FIGURES`
is the LCCA task as the figures draw it (`study.analysis.task_figures`)."""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd
from matplotlib.axes import Axes

from study.analysis.task_figures import FigureView, register_figures
from study.protocol.tasks import LiveTrace
from teleop_core.phantom.lcca import LccaPhantom

CONDITION_COLORS = {"VO": "C3", "HV": "C0"}


def draw_phantom(phantom: LccaPhantom, ax: Axes | None = None) -> Axes:
    """The arch and its branches in the frontal (x-z) plane, vessel widths to scale."""
    ax = ax or plt.gca()
    anatomy = phantom.anatomy
    diameters = [anatomy.aorta_diameter_m] + [b.diameter_m for b in anatomy.branches]
    # points per mm (the axes are in mm), so a line is as wide as its vessel
    fig = ax.figure
    fig.canvas.draw()
    x0, x1 = ax.get_xlim()
    width_in = ax.get_window_extent().width / fig.dpi
    pts_per_mm = width_in * 72 / (x1 - x0)
    for path, diameter in enumerate(diameters):
        c = phantom.centreline(path) * 1000
        ax.plot(
            c[:, 0],
            c[:, 2],
            color="0.85",
            lw=diameter * 1000 * pts_per_mm,
            solid_capstyle="round",
            zorder=0,
        )
    for path in range(len(diameters)):
        c = phantom.centreline(path) * 1000
        ax.plot(c[:, 0], c[:, 2], color="0.6", lw=0.5, ls=":", zorder=1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("z (mm)")
    return ax


def plot_tip_paths(
    phantom: LccaPhantom,
    trials: Sequence[tuple[pd.DataFrame, str]],
    ax: Axes | None = None,
    contact_threshold_n: float = 0.2,
) -> Axes:
    """Tip paths of several trials on the phantom, coloured by condition (VO / HV).

    The wire follows the centreline, so paths overlap; where the tip pressed a wall
    (distal force above `contact_threshold_n`) a circle marks the spot, its area
    proportional to the peak force there.
    """
    ax = ax or plt.gca()
    ax.set_xlim(-120, 50)
    ax.set_ylim(120, 360)
    draw_phantom(phantom, ax)
    seen = set()
    for frame, condition in trials:
        color = CONDITION_COLORS.get(condition, "k")
        label = condition if condition not in seen else None
        seen.add(condition)
        ax.plot(
            frame["tip_x_m"] * 1000,
            frame["tip_z_m"] * 1000,
            lw=0.8,
            alpha=0.7,
            color=color,
            label=label,
        )
        pressed = frame[frame["distal_force_n"] > contact_threshold_n]
        if len(pressed):
            ax.scatter(
                pressed["tip_x_m"] * 1000,
                pressed["tip_z_m"] * 1000,
                s=60 * pressed["distal_force_n"],
                facecolors="none",
                edgecolors=color,
                linewidths=0.6,
                alpha=0.5,
            )
    ax.legend(fontsize=7, loc="lower left")
    return ax


def plot_trial(frame: pd.DataFrame, phantom: LccaPhantom, title: str = "") -> plt.Figure:
    """Forces over time (estimated proximal, reference, distal) and the tip path."""
    fig = plt.figure(figsize=(7.16, 3.2), layout="constrained")
    grid = fig.add_gridspec(1, 2, width_ratios=(1.6, 1))
    ax = fig.add_subplot(grid[0])
    ax.plot(
        frame["t_s"], frame["reference_force_n"], color="0.6", lw=0.8, label="proximal (reference)"
    )
    ax.plot(
        frame["t_s"], frame["proximal_force_n"], color="C0", lw=0.9, label="proximal (estimated)"
    )
    ax.plot(frame["t_s"], frame["distal_force_n"], color="C3", lw=0.9, label="distal")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (N)")
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    path_ax = fig.add_subplot(grid[1])
    path_ax.set_xlim(-120, 50)
    path_ax.set_ylim(120, 360)
    draw_phantom(phantom, path_ax)
    path_ax.plot(frame["tip_x_m"] * 1000, frame["tip_z_m"] * 1000, color="C0", lw=0.9)
    return fig


def trial_figure(frame: pd.DataFrame, title: str) -> plt.Figure:
    """`plot_trial` on the task's phantom: the figure `study simulate --plot` draws."""
    return plot_trial(frame, LccaPhantom(), title)


FIGURES = register_figures(
    "lcca",
    FigureView(
        traces=(
            LiveTrace("proximal_force_n", "proximal", 2.0),
            LiveTrace("distal_force_n", "distal", 1.0),
        ),
        trace_names={
            "reference_force_n": "proximal, reference",
            "proximal_force_n": "proximal, estimated",
            "distal_force_n": "distal (tip on wall)",
        },
        sign_note=(
            "Proximal force: positive resists insertion (pushing the wire in), negative "
            "resists withdrawal. Distal force: tip-wall contact, ≥\u00a00."
        ),
        trial_figure=trial_figure,
    ),
)
