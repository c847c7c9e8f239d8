"""Fig. 9: the forces of one participant's VO and HV trial, in one figure.

VO and HV panels share the time axis and the y-axis so that the forces compare at a glance; the
reference force is drawn above (zorder) the estimate it is compared with; the caption
(`captions.md`, from `FigureView.sign_note`) states the sign convention of the task's model:

- lcca (`teleop_core.phantom.lcca`): the proximal force is what the drive feels, the
  wall and sliding friction resisting the wire; positive while inserting, negative
  while withdrawing (friction follows the speed's sign). The distal force is the tip's
  contact force on the vessel wall, never negative.
- notes (`teleop_core.notes.task`): the demanded force is the tissue's resistance on
  the scope, positive resisting insertion; the rendered force is what the device
  applies (it saturates at its continuous limit); the tip force is the fornix's push.

Sample columns under the task's own names; which of them a task traces, under what
labels and with which sign convention, its figure view says
(`study.analysis.task_figures.FigureView`: `trace_names`, `sign_note`).
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import pandas as pd

from study.analysis.figures import STYLE, WIDTHS_IN, figure_legend
from study.analysis.task_figures import figure_view
from study.protocol.tasks import get_task

STYLES = (
    # the reference on top of the estimate, thin and dark over a wide light line
    {"color": "black", "lw": 0.7, "zorder": 3},
    {"color": "#56B4E9", "lw": 1.6, "zorder": 2},
    {"color": "#D55E00", "lw": 0.9, "zorder": 1},
)
"""The styles of a task's traces, in the order of its `trace_names` (LCCA: reference,
estimate, distal)."""


def force_traces(
    trials: list[tuple[pd.DataFrame, str]], task: str = "lcca", width: str = "double"
) -> plt.Figure:
    """One panel per trial (VO, then HV), sharing the y-axis.

    Parameters
    ----------
    trials
        (samples, title) per panel; samples with t_s and the force columns (N).
    task
        The task whose `trace_names` and `sign_note` name the traces and the sign
        convention (`study.protocol.tasks`).
    width
        'single' (panels stacked) or 'double' (side by side).
    """
    the_task = get_task(task)
    names = figure_view(the_task).traced_names()
    with plt.rc_context(STYLE):
        rows, cols = (len(trials), 1) if width == "single" else (1, len(trials))
        height = 1.6 * rows + 1.1
        # one time axis and one force axis for both trials: they compare at a glance
        fig, axes = plt.subplots(
            rows,
            cols,
            figsize=(WIDTHS_IN[width], height),
            sharey=True,
            sharex=True,
            layout="constrained",
            squeeze=False,
        )
        for ax, (samples, title) in zip(axes.ravel(), trials, strict=True):
            for k, (column, label) in enumerate(names.items()):
                if column in samples and samples[column].notna().any():
                    style = STYLES[k] if k < len(STYLES) else {}
                    ax.plot(samples["t_s"], samples[column], label=label, **style)
            ax.axhline(0.0, color="#999999", lw=0.4, zorder=0)
            ax.set_title(title)
        for ax in axes[-1, :]:
            ax.set_xlabel("time (s)")
        for ax in axes[:, 0]:
            ax.set_ylabel("force (N)")
        handles, _ = axes.ravel()[0].get_legend_handles_labels()
        figure_legend(fig, handles, 3 if width == "double" else 2)
    return fig
