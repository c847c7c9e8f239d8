"""Progress where stderr is no terminal: a plain line every ten seconds.

A Rich bar or spinner draws nothing on a pipe or a log file, so a lab's scripted run
(`study demo --out d > log 2>&1`) looked hung until its last line. `progress_bar` and
`progress_status` (in `base`) hand out these stand-ins there: the same interface as
Rich's `Progress` and `Status` for what the commands call, the tasks kept by Rich
itself, and a `teleop_core.progress.Heartbeat` writing what is done and what remains
every `HEARTBEAT_S` seconds. This module imports Rich, so it is imported only then.
"""

from __future__ import annotations

from typing import Any

import click
from rich.console import Console
from rich.progress import Progress, Task

from teleop_core.progress import HEARTBEAT_S, Heartbeat, clock_text


def command_label() -> str:
    """`study CMD` of the running command, the head of each line."""
    ctx = click.get_current_context(silent=True)
    return ctx.command_path if ctx is not None else "study"


def task_line(task: Task) -> str:
    """One Rich task as done and remaining: ``"participants: 12/36, 24 to go, about 3 min
    left"`` (the `what` field, where a command keeps its step, after the description)."""
    text = task.description
    what = task.fields.get("what")
    if what:
        text += f" ({what})"
    if task.total:
        unit = task.fields.get("unit", "")
        done, total = int(task.completed), int(task.total)
        text += f": {done}/{total}{' ' + unit if unit else ''}, {max(total - done, 0)} to go"
        if task.time_remaining is not None and 0 < done < total:
            text += f", about {clock_text(task.time_remaining)} left"
    elif task.completed:
        text += f": {int(task.completed)} done"
    return text


def _printer(console: Console) -> Any:
    def write(line: str) -> None:
        console.print(line, markup=False, highlight=False, soft_wrap=True)

    return write


class LineProgress(Progress):
    """A Rich `Progress` that draws nothing and writes `task_line` of its unfinished
    tasks every `interval_s` seconds."""

    def __init__(self, *columns: Any, console: Console, interval_s: float = HEARTBEAT_S) -> None:
        super().__init__(*columns, console=console, disable=True)
        self.heartbeat = Heartbeat(
            _printer(console), command_label(), interval_s, summary=self.summary
        )

    def summary(self) -> str:
        shown = [t for t in self.tasks if t.visible and not t.finished] or self.tasks
        return "; ".join(task_line(t) for t in shown) or "starting"

    def __enter__(self) -> LineProgress:
        super().__enter__()
        self.heartbeat.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.heartbeat.__exit__(*exc)
        super().__exit__(*exc)


class LineStatus(Heartbeat):
    """A Rich `Status` stand-in: `update(text)` records the step, `console` prints."""

    def __init__(self, text: str, console: Console, interval_s: float = HEARTBEAT_S) -> None:
        super().__init__(_printer(console), command_label(), interval_s)
        self.console = console
        self.update(text)
