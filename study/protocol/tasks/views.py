"""What the terminal app's live views and the analysis' figure views of tasks share: a
registry of views by task name (the built-in tasks' view modules imported, installed
packages' entry points read, both once, on first use) and the traces of a task nobody
registered a view for. Each side keeps its own view type (`study.tui.task_views`,
`study.analysis.task_figures`); this module imports neither.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Generic, TypeVar

from study.protocol.tasks.declarations import LiveTrace

if TYPE_CHECKING:
    from study.protocol.tasks.task import Task

V = TypeVar("V")
POSE = ("t_s", "tip_x_m", "tip_y_m", "tip_z_m")
"""Pose columns no default view traces (with the region and the insertion and roll)."""


class ViewRegistry(Generic[V]):
    """Views by task name: `register` replaces, `get` finds (None: none registered)."""

    def __init__(self, builtin: tuple[str, ...], group: str) -> None:
        self._builtin = builtin
        self._group = group
        self._views: dict[str, V] = {}
        self._loaded = False

    def register(self, name: str, view: V) -> V:
        """Draw the task called `name` with `view` (replacing one it had); `view` returned."""
        self._views[name] = view
        return view

    def get(self, name: str) -> V | None:
        if not self._loaded:
            self._loaded = True
            for module in self._builtin:
                importlib.import_module(module)
            for entry in entry_points(group=self._group):
                self._views.setdefault(entry.name, entry.load())
        return self._views.get(name)


def default_traces(task: Task) -> tuple[LiveTrace, LiveTrace]:
    """A task's first two sample columns after the pose and the region (the one column
    twice when it has one), each under its name at a full scale of 1 in its unit."""
    skip = {*POSE, task.region_column, task.sample_columns[1].name, task.sample_columns[2].name}
    rest = [c for c in task.sample_columns if c.name not in skip] or list(task.sample_columns)
    first, second = (rest * 2)[:2]
    return LiveTrace(first.name, first.name, 1.0), LiveTrace(second.name, second.name, 1.0)
