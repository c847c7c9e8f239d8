"""The figure `study simulate --plot` draws of one trial: the task's own
(`FigureView.trial_figure`, drawn by its package), or, for a task without one, the
insertion and the view's traced forces over time (`traces_plot`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import matplotlib.pyplot as plt

from study.analysis.figures import STYLE, WIDTHS_IN
from study.analysis.task_figures import figure_view

if TYPE_CHECKING:
    import pandas as pd

    from study.protocol.tasks import Task


def trial_plot(task: Task, frame: pd.DataFrame, title: str) -> plt.Figure:
    """The task's own figure of one trial (`FigureView.trial_figure`), else `traces_plot`."""
    draw = figure_view(task).trial_figure
    return traces_plot(task, frame, title) if draw is None else draw(frame, title)


def traces_plot(task: Task, frame: pd.DataFrame, title: str) -> plt.Figure:
    """Insertion (top) and the view's traced forces (bottom) against time."""
    t = frame[task.sample_columns[0].name]
    with plt.rc_context(STYLE):
        fig, (top, bottom) = plt.subplots(
            2, 1, sharex=True, figsize=(WIDTHS_IN["single"], 2.6), layout="constrained"
        )
        depth = frame[task.sample_columns[1].name]  # `pose_columns`: time, insertion, ...
        top.plot(t, depth * 1e3, color="black", lw=0.8)
        top.set_ylabel("inserted (mm)")
        for trace, color in zip(figure_view(task).traces, ("#0072B2", "#D55E00"), strict=False):
            unit = next(c.unit for c in task.sample_columns if c.name == trace.column)
            bottom.plot(
                t, frame[trace.column], color=color, lw=0.8, label=f"{trace.label} ({unit})"
            )
        bottom.set_xlabel("time (s)")
        bottom.legend(loc="upper left", frameon=False)
        top.set_title(title)
    return fig
