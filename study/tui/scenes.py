"""What the run screen draws beside its readout: the scene of the trial's task's view
(`study.tui.task_views.LiveView.scene`), or, for a view without one, the insertion along
a track (`TrackView`). `SceneView` is the base of scenes redrawn whole at each frame of
the live view.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Protocol

from rich.text import Text
from textual.widget import Widget

from study.tui.live_view import TIP_STYLE
from study.tui.task_views import live_view
from study.tui.trial_runner import LiveFrame

if TYPE_CHECKING:
    from study.protocol.tasks import Task


def axis_column(value: float, lo: float, hi: float, cols: int) -> int:
    """The column of `value` on an axis from lo (column 0) to hi (column cols - 1)."""
    return min(max(round((cols - 1) * (value - lo) / (hi - lo)), 0), cols - 1)


class LiveScene(Protocol):
    """What the run screen asks of a task's live scene (`Task.live_scene`, a widget)."""

    def update_frame(self, frame: LiveFrame | None) -> None: ...


class SceneView(Widget):
    """A scene (`scene(frame, columns) -> Text`) redrawn whole at each frame."""

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self._frame: LiveFrame | None = None

    def update_frame(self, frame: LiveFrame | None) -> None:
        self._frame = frame
        self.refresh()

    def scene(self, frame: LiveFrame | None, cols: int) -> Text:
        raise NotImplementedError

    def render(self) -> Text:
        return self.scene(self._frame, self.size.width)


def track_scene(frame: LiveFrame | None, cols: int) -> Text:
    """Any task's tip as text: its insertion along a bar of its view's `track_length_m`,
    the region it is in, and its roll."""
    cols = max(cols, 20)
    text = Text(no_wrap=True, overflow="crop")
    if frame is None:
        text.append("(no sample yet)")
        return text
    task = frame.task
    region = task.regions[frame.branch] if 0 <= frame.branch < len(task.regions) else "?"
    text.append(f"inserted {frame.insertion_m * 1000:5.0f} mm   in {region}\n")
    at = axis_column(frame.insertion_m, 0.0, live_view(task).track_length_m, cols)
    text.append("━" * at, "bold")
    text.append("●", TIP_STYLE)
    text.append("─" * max(cols - at - 1, 0) + "\n", "dim")
    text.append(f"\nroll {math.degrees(frame.rotation_rad):+5.0f} deg")
    return text


class TrackView(SceneView):
    """`track_scene`: the view of a task without its own."""

    DEFAULT_CSS = """
    TrackView { width: 1fr; height: 1fr; min-height: 4; background: $surface; }
    """

    def scene(self, frame: LiveFrame | None, cols: int) -> Text:
        return track_scene(frame, cols)


def scene_class(task: Task) -> type[Widget]:
    """The widget class of `task`'s live scene, else `TrackView`."""
    scene = live_view(task).scene
    return TrackView if scene is None else scene


def scene_title(task: Task) -> str:
    """The live view's border title for `task`."""
    return live_view(task).scene_title.format(title=task.title)
