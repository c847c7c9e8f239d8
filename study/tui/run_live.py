"""The run screen's live view and keyboard, as mixins of `RunPane`.

`LiveViewMixin`: what the 30 Hz timer draws from `LiveState` (never from the worker):
the scene of the trial's task's view (`study.tui.task_views.LiveView`, or the insertion
along a track) and the readout of the view's two live forces and its own lines.
`KeyboardMixin`: the pane's key actions, handed to the keyboard driver.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, cast

from rich.text import Text

from study.tui.live_view import LiveReadout, gauge, sparkline
from study.tui.scenes import LiveScene, scene_class, scene_title
from study.tui.task_views import live_view
from study.tui.trial_summary import report_lines

if TYPE_CHECKING:
    from collections import deque

    from textual.widget import Widget

    from study.protocol.tasks import Task
    from study.tui.trial_runner import LiveFrame, TrialRun
    from study.tui.trial_summary import TrialReport

    _Pane = Widget
else:
    _Pane = object  # the pane it joins (RunPane) is the widget

KEY_ACTIONS = {
    "dial_forward": "advance",
    "dial_back": "retract",
    "rotate_cw": "rotate_cw",
    "rotate_ccw": "rotate_ccw",
    "release": "release",
    "end_trial": "stop",
}
"""Pane action -> `KeyboardDriver.press` key."""


def task_lines(frame: LiveFrame) -> list[str]:
    """The readout lines of the task's view (`LiveView.lines`) for `frame`."""
    return live_view(frame.task).lines(frame.task, frame.values, frame.condition)


class LiveViewMixin(_Pane):
    """The live view of `RunPane` (which provides run, status, last_outcome, last_report,
    _redraws)."""

    run: TrialRun | None
    status: str
    last_outcome: str
    last_report: tuple[str, TrialReport, str] | None
    _redraws: deque[float]

    def _show_task(self, task: Task) -> None:
        """The live view of `task`'s trials: the scene of its view
        (`LiveView.scene`), mounted on first use, or the insertion along a track."""
        shown = scene_class(task)
        box = self.query_one("#phantom-box")
        box.border_title = scene_title(task)
        if not box.query(shown):
            box.mount(shown())
        for view in box.children:
            view.display = type(view) is shown

    @property
    def redraw_hz(self) -> float:
        """Redraws per second over the last 50 redraws during a trial."""
        r = self._redraws
        return (len(r) - 1) / (r[-1] - r[0]) if len(r) > 1 and r[-1] > r[0] else 0.0

    def _redraw(self) -> None:
        run = self.run
        frame = run.live.frame() if run is not None else None
        readout = self.query_one(LiveReadout)
        if run is None or frame is None:
            self._redraws.clear()
            text = Text(f"status: {self.status}")
            if run is None and self.last_outcome:
                text.append(f"\n{self._outcome_text(readout)}", "bold")
            readout.show(text)
            return
        self._redraws.append(time.monotonic())
        width = max(readout.content_size.width, 10)
        text = Text(f"t {frame.t_s:6.1f} s   status: {self.status}\n", no_wrap=True)
        text.append(f"view {self.redraw_hz:4.1f} Hz\n", "dim")
        scene = cast("LiveScene", self.query_one(scene_class(frame.task)))
        scene.update_frame(frame)
        text.append_text(self._readout(frame, width, run))
        readout.show(text)

    def _outcome_text(self, readout: LiveReadout) -> str:
        """The last outcome in the readout's rows under the status line (a block's
        summary whole, before the trial's own figures)."""
        shown = self.last_report
        if shown is None or shown[2] != self.last_outcome:
            return self.last_outcome
        code, report, _ = shown
        return "\n".join(report_lines(code, report, max(readout.content_size.height - 1, 3)))

    def _readout(self, frame: LiveFrame, width: int, run: TrialRun) -> Text:
        """The task's two live forces (gauge and history), then its own lines."""
        text = Text()
        histories = (frame.first_history, frame.second_history)
        for k, trace in enumerate(live_view(frame.task).traces):
            value = frame.values[trace.column]  # signed; the bar shows |value| if magnitude
            text.append_text(
                gauge(trace.label, value, trace.full_scale, 14, magnitude=trace.magnitude)
            )
            text.append("\n" + sparkline(histories[k], width, trace.full_scale) + "\n\n")
        lines = task_lines(frame)
        wait = run.live.storage_wait
        if wait is not None:  # the trial goes on; its samples wait in memory
            lines.insert(
                0,
                f"waiting for the database (locked by another program) "
                f"{wait[0]:.0f} s: {wait[1]} samples held, none lost",
            )
        if run.keyboard is not None:
            aim = live_view(frame.task).keyboard_aim_label
            lines.append(f"{aim} {run.keyboard.aim_rad:+4.2f} rad")
        text.append("\n".join(lines))
        return text


class KeyboardMixin:
    """The pane's keys, pressed on the running trial's keyboard driver."""

    run: TrialRun | None

    def _press(self, action: str) -> None:
        run = self.run
        if run is not None and run.keyboard is not None:
            run.keyboard.press(KEY_ACTIONS[action])

    def action_dial_forward(self) -> None:
        self._press("dial_forward")

    def action_dial_back(self) -> None:
        self._press("dial_back")

    def action_rotate_cw(self) -> None:
        self._press("rotate_cw")

    def action_rotate_ccw(self) -> None:
        self._press("rotate_ccw")

    def action_release(self) -> None:
        self._press("release")

    def action_end_trial(self) -> None:
        self._press("end_trial")
