"""The figure of one NOTES trial (`study simulate --plot`): depth, demanded vs rendered
force and torque over time, with the device's continuous force limit. `FIGURES` is the
NOTES task as the figures draw it (`study.analysis.task_figures`).

House style of `study.analysis.figures` (IEEE widths, Okabe-Ito colours).
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import pandas as pd

from study.analysis.figures import OKABE_ITO, STYLE, WIDTHS_IN
from study.analysis.task_figures import FigureView, register_figures
from study.protocol.tasks import LiveTrace

MEASURED = OKABE_ITO["grey"]
MODEL = OKABE_ITO["HV"]
BEFORE = OKABE_ITO["VO"]


def notes_trial_plot(frame: pd.DataFrame, title: str = "") -> plt.Figure:
    """A NOTES trial: depth, demanded vs rendered force and torque over time."""
    with plt.rc_context(STYLE):
        fig, (a0, a1, a2) = plt.subplots(3, 1, figsize=(WIDTHS_IN["single"], 4.2), sharex=True)
        t = frame["t_s"]
        a0.plot(t, frame["insertion_m"] * 1e3, color=MEASURED)
        a0.set_ylabel("depth (mm)")
        a0.set_title(title)
        a1.plot(t, frame["force_demanded_n"], color=BEFORE, label="demanded")
        a1.plot(t, frame["force_rendered_n"], color=MODEL, label="rendered")
        a1.axhline(5.62, color=MEASURED, lw=0.5, ls="--", label="device limit")
        a1.set_ylabel("force (N)")
        a1.legend(frameon=False, loc="upper left")
        a2.plot(t, frame["torque_demanded_n_m"] * 1e3, color=BEFORE)
        a2.plot(t, frame["torque_rendered_n_m"] * 1e3, color=MODEL)
        a2.set_ylabel("torque (N mm)")
        a2.set_xlabel("time (s)")
        fig.tight_layout()
    return fig


FIGURES = register_figures(
    "notes",
    FigureView(
        traces=(
            LiveTrace("force_demanded_n", "demanded", 10.0, magnitude=True),
            LiveTrace("force_rendered_n", "rendered", 10.0, magnitude=True),
        ),
        trace_names={
            "force_demanded_n": "demanded (tissue)",
            "force_rendered_n": "rendered (device)",
            "tip_force_n": "tip (fornix)",
        },
        sign_note=(
            "Force on the scope: positive resists insertion (pushing in), negative "
            "resists withdrawal. Tip force: the fornix on the tip, ≥\u00a00."
        ),
        trial_figure=notes_trial_plot,
    ),
)
