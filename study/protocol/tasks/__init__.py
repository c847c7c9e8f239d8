"""Tasks: what a trial is, in one place per task, and the registry that knows them.

A task (the LCCA guidewire navigation, the NOTES endoscopy, or one a lab adds) is a
`Task` (`study.protocol.tasks.task`): a declaration of its regions, sample columns and
summary measures, and three hooks that build the trial's closed loop, the simulated
participant's driver and the trial's measures. The session runner, `study simulate`,
`study run`, the exports, the analysis and the TUI ask the registry (`get_task`,
`task_names`); nothing outside a task's module compares task names.

The built-in tasks are listed in `BUILTIN`; `register(task)` adds one (a test, a lab's
own module), and installed packages may add theirs under the entry-point group
`haptic_study.tasks` (each entry point names a `Task` instance). "Adding a task" in the
README walks through it.

This module imports nothing heavy (the TUI and `study` read designs before numpy loads):
a task's module imports its loop and its numerics inside its methods.
"""

from __future__ import annotations

import importlib

from study.errors import StudyInputError
from study.protocol.tasks.declarations import (
    LiveTrace,
    Measure,
    SampleColumn,
    described,
    pose_columns,
)
from study.protocol.tasks.task import (
    COMPLETION_TIME,
    Task,
    TaskDeclaration,
    Traits,
    TrialLoop,
    TrialResult,
)

BUILTIN = ("study.tasks.lcca.task", "study.tasks.notes.task")
"""The modules of the tasks that come with the tool, each registering its `TASK`."""
__all__ = [
    "COMPLETION_TIME",
    "LiveTrace",
    "Measure",
    "SampleColumn",
    "Task",
    "TaskDeclaration",
    "Traits",
    "TrialLoop",
    "TrialResult",
    "described",
    "get_task",
    "is_task",
    "measure_named",
    "pose_columns",
    "register",
    "task_names",
    "tasks",
    "unregister",
]
ENTRY_POINT_GROUP = "haptic_study.tasks"


_REGISTRY: dict[str, Task] = {}
_LOADED = _ENTRY_POINTS_LOADED = False


def register(task: Task) -> Task:
    """Add `task` to the registry, replacing one of the same name.

    Parameters
    ----------
    task : Task
        A `Task` instance.

    Returns
    -------
    Task
        `task` itself (so a module can write ``TASK = register(MyTask())``).

    Raises
    ------
    ValueError
        Its name is not an identifier of at most 16 characters, or its sample columns
        do not start with the six `pose_columns` or lack its region column.
    """
    if not getattr(task, "name", "") or not task.name.isidentifier() or len(task.name) > 16:
        raise ValueError(
            f"task name {getattr(task, 'name', None)!r}; expected an identifier "
            "of at most 16 characters"
        )
    names = [c.name for c in task.sample_columns]
    if names[:1] != ["t_s"] or len(names) < 6 or task.region_column not in names:
        raise ValueError(
            f"task {task.name}: sample columns {names}; expected the six `pose_columns` "
            f"first and the region column {task.region_column!r} among them"
        )
    _REGISTRY[task.name] = task
    return task


def unregister(name: str) -> None:
    """Remove the task called `name` from the registry (nothing if there is none)."""
    _REGISTRY.pop(name, None)


def _load(entry_points_too: bool = False) -> None:
    """The built-in tasks on first use; the installed packages' (entry points: a scan of
    every distribution's metadata) only when a name is not built in or all are asked for."""
    global _LOADED, _ENTRY_POINTS_LOADED
    if not _LOADED:
        _LOADED = True
        for module in BUILTIN:
            importlib.import_module(module)
    if entry_points_too and not _ENTRY_POINTS_LOADED:
        _ENTRY_POINTS_LOADED = True
        from importlib.metadata import entry_points

        for entry in entry_points(group=ENTRY_POINT_GROUP):
            register(entry.load())


def is_task(name: str) -> bool:
    """Whether a task called `name` is built in, registered or installed."""
    _load()
    if name not in _REGISTRY:
        _load(entry_points_too=True)
    return name in _REGISTRY


def task_names() -> tuple[str, ...]:
    """The tasks a design may name.

    Returns
    -------
    tuple of str
        The built-in tasks' names first, then those registered or installed (entry
        point group ``haptic_study.tasks``).
    """
    _load(entry_points_too=True)
    return tuple(_REGISTRY)


def get_task(name: str) -> Task:
    """The task called `name`.

    Parameters
    ----------
    name : str
        A task's name, e.g. ``"lcca"``.

    Returns
    -------
    Task
        The registered task.

    Raises
    ------
    StudyInputError
        No task has that name; the one-line message lists the known ones.
    """
    if not is_task(name):
        raise StudyInputError(not_installed(name))
    return _REGISTRY[name]


INSTALL_HINTS = {"probe": "study example-data DIR && pip install DIR/probe_task"}
"""How to install the tasks whose packages ship with haptic-study as examples."""


def not_installed(name: str) -> str:
    """The one line for a task name no built-in task or installed package has: the task
    is named as not installed, with how to install it where that is known."""
    how = INSTALL_HINTS.get(
        name, f"pip install the package whose {ENTRY_POINT_GROUP} entry point is {name!r}"
    )
    return f"task {name!r} is not installed: {how}; installed: {', '.join(task_names())}"


def measure_named(name: str) -> Measure | None:
    """The measure called `name` in the first registered task that has it."""
    for task in tasks():
        for m in task.all_measures:
            if m.name == name:
                return m
    return None


def tasks() -> tuple[Task, ...]:
    """Every known task, in `task_names`' order."""
    _load(entry_points_too=True)
    return tuple(_REGISTRY.values())
