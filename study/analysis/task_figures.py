"""What the figures draw of a task: a `FigureView` per task, kept on the analysis' side
so that a task (`study.protocol.tasks.Task`) declares its data and hooks only.

The built-in tasks' views are in their packages' figure modules (`BUILTIN`, imported by
name: the analysis names no task); `register_figures` adds one, and installed packages
may add theirs under the entry-point group `haptic_study.figure_views` (each entry point
names a `FigureView`, under the task's name). A task without one gets `default_figures`:
its first two sample columns after the pose and the region.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from study.protocol.tasks import COMPLETION_TIME, LiveTrace, Task
from study.protocol.tasks.views import ViewRegistry, default_traces

if TYPE_CHECKING:
    import pandas as pd

BUILTIN = ("study.tasks.lcca.figures", "study.tasks.notes.figures")
"""The modules of the built-in tasks' figures, each registering its `FIGURES`."""
ENTRY_POINT_GROUP = "haptic_study.figure_views"


@dataclass(frozen=True)
class FigureView:
    """A task as the figures draw it."""

    traces: tuple[LiveTrace, ...]
    """The forces `study simulate --plot` draws under the insertion for a task without
    its own `trial_figure`."""
    trace_names: Mapping[str, str] = field(default_factory=dict)
    """Force columns (the task's sample column names) -> legend label, for the
    force-trace figure, in the order of `study.analysis.trace_figure.STYLES`; empty:
    the `traces`' columns under their labels."""
    sign_note: str = ""
    """The sign convention of the traced forces, under the figure."""
    trace_measure: str | None = None
    """The measure whose highest VO trial Fig. 9 draws (None: the last analysed one)."""
    trial_figure: Callable[[pd.DataFrame, str], Any] | None = None
    """The figure of one trial's TRIAL.csv frame under a title (`study simulate
    --plot`); None: the insertion and the `traces` over time."""

    def traced_names(self) -> dict[str, str]:
        """`trace_names`, else the `traces`' columns and labels."""
        return dict(self.trace_names) or {t.column: t.label for t in self.traces}


_VIEWS: ViewRegistry[FigureView] = ViewRegistry(BUILTIN, ENTRY_POINT_GROUP)


def register_figures(name: str, view: FigureView) -> FigureView:
    """Draw the task called `name` with `view` (replacing one it had); `view` returned."""
    return _VIEWS.register(name, view)


def default_figures(task: Task) -> FigureView:
    """The figures of a task nobody registered a view for: its first two sample columns
    after the pose and the region, under their names."""
    return FigureView(tuple(dict.fromkeys(default_traces(task))))  # one column: one trace


def figure_view(task: Task) -> FigureView:
    """The view `task` is drawn with: its registered one, else `default_figures`."""
    view = _VIEWS.get(task.name)
    return view if view is not None else default_figures(task)


def trace_measure(task: Task) -> str:
    """The measure whose highest VO trial Fig. 9 draws: the view's, else the task's last
    analysed measure (`completion_time_s` where none is)."""
    chosen = figure_view(task).trace_measure
    if chosen:
        return chosen
    analysed = [m.name for m in task.measures if m.analysed]
    return analysed[-1] if analysed else COMPLETION_TIME
