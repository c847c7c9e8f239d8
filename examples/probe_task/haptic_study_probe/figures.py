"""The probe task in haptic-study's figures: the push force traced under its sign
convention (no figure of its own: `study simulate --plot` draws the insertion and the
traces over time). The entry point `haptic_study.figure_views: probe` names `FIGURES`."""

from __future__ import annotations

from study.analysis.task_figures import FigureView
from study.protocol.tasks import LiveTrace

FIGURES = FigureView(
    traces=(LiveTrace("push_force_n", "push", 2.0), LiveTrace("aim_rad", "aim", 1.0)),
    trace_names={"push_force_n": "push (medium)"},
    sign_note="Push force: positive resists insertion.",
)
