"""The scenes drawn beside the run screen's readout for tasks without the LCCA phantom:
the NOTES scope's depth and roll (`notes_scene`), and any task's insertion along a track
(`track_scene`). Each is a widget redrawn whole at each frame of the live view.
"""

from __future__ import annotations

import math

from rich.text import Text
from textual.widget import Widget

from study.tui.live_view import TARGET_STYLE, TIP_STYLE
from study.tui.trial_runner import LiveFrame

NOTES_DEPTH_PAST_TARGET_M = 0.02
"""How far past the NOTES target the depth axis runs."""
NOTES_ROLL_SPAN_RAD = math.pi / 2
"""The roll axis runs from -90 to +90 degrees."""


def _axis_column(value: float, lo: float, hi: float, cols: int) -> int:
    """The column of `value` on an axis from lo (column 0) to hi (column cols - 1)."""
    return min(max(round((cols - 1) * (value - lo) / (hi - lo)), 0), cols - 1)


def notes_region(code: int) -> str:
    from teleop_core.notes.task import REGIONS

    return REGIONS[code] if 0 <= code < len(REGIONS) else "?"


def notes_scene(frame: LiveFrame | None, cols: int) -> Text:
    """The NOTES scope as text: its depth from the introitus and its roll, each on an axis
    with the posterior fornix and the target marked (`teleop_core.notes.task`)."""
    from teleop_core.notes.task import (
        FORNIX_M,
        TARGET_M,
        TARGET_ROLL_RAD,
        TARGET_ROLL_TOLERANCE_RAD,
        TARGET_TOLERANCE_M,
    )

    cols = max(cols, 20)
    end_m = TARGET_M + NOTES_DEPTH_PAST_TARGET_M
    depth = frame.insertion_m if frame is not None else 0.0
    roll = frame.rotation_rad if frame is not None else 0.0
    breached = frame is not None and notes_region(frame.branch) in ("cavity", "target", "fold")

    def column(depth_m: float) -> int:
        return _axis_column(depth_m, 0.0, end_m, cols)

    def roll_column(roll_rad: float) -> int:
        return _axis_column(roll_rad, -NOTES_ROLL_SPAN_RAD, NOTES_ROLL_SPAN_RAD, cols)

    def axis(marks: dict[int, tuple[str, str]], zone: range) -> None:
        """One axis line: `marks` (column -> character, style) over the target zone."""
        for c in range(cols):
            if c in marks:
                text.append(*marks[c])
            elif c in zone:
                text.append("▓", TARGET_STYLE)
            else:
                text.append("─", "dim")
        text.append("\n")

    text = Text(no_wrap=True, overflow="crop")
    where = f"in the {notes_region(frame.branch)}" if frame is not None else "(no sample yet)"
    text.append(f"depth {depth * 1000:5.0f} mm   {where}\n")
    # the canal, the fornix (dim once breached) and the target zone; then the scope
    fornix = column(FORNIX_M)
    target = range(column(TARGET_M - TARGET_TOLERANCE_M), column(TARGET_M + TARGET_TOLERANCE_M) + 1)
    axis({fornix: ("┃", "dim" if breached else "bold")}, target)
    text.append("━" * column(depth), "bold")
    text.append("●\n", TIP_STYLE)
    labels = [" "] * cols
    for at, word in ((0, "introitus"), (fornix, "fornix"), (target.start, "target")):
        for k, ch in enumerate(word[: max(cols - at, 0)]):
            labels[at + k] = ch
    text.append("".join(labels), "dim")
    # the roll: the scope's mark over the zero mark and the target zone
    text.append(
        f"\n\nroll {math.degrees(roll):+5.0f} deg   target "
        f"{math.degrees(TARGET_ROLL_RAD):+.0f} +/- {math.degrees(TARGET_ROLL_TOLERANCE_RAD):.0f}\n"
    )
    zero = roll_column(0.0)
    target_roll = range(
        roll_column(TARGET_ROLL_RAD - TARGET_ROLL_TOLERANCE_RAD),
        roll_column(TARGET_ROLL_RAD + TARGET_ROLL_TOLERANCE_RAD) + 1,
    )
    axis({zero: ("┼", "dim"), roll_column(roll): ("●", TIP_STYLE)}, target_roll)
    left = f"-{math.degrees(NOTES_ROLL_SPAN_RAD):.0f}"
    right = f"+{math.degrees(NOTES_ROLL_SPAN_RAD):.0f}"
    scale = (left + " " * max(zero - len(left), 1) + "0").ljust(cols - len(right))
    text.append(scale[: cols - len(right)] + right, "dim")
    return text


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


class NotesView(SceneView):
    """The NOTES scope's depth and roll (`notes_scene`)."""

    DEFAULT_CSS = """
    NotesView { width: 1fr; height: 1fr; min-height: 8; background: $surface; }
    """

    def scene(self, frame: LiveFrame | None, cols: int) -> Text:
        return notes_scene(frame, cols)


def track_scene(frame: LiveFrame | None, cols: int) -> Text:
    """Any task's tip as text: its insertion along a bar of the task's `track_length_m`,
    the region it is in, and its roll."""
    cols = max(cols, 20)
    text = Text(no_wrap=True, overflow="crop")
    if frame is None:
        text.append("(no sample yet)")
        return text
    task = frame.task
    region = task.regions[frame.branch] if 0 <= frame.branch < len(task.regions) else "?"
    text.append(f"inserted {frame.insertion_m * 1000:5.0f} mm   in {region}\n")
    at = _axis_column(frame.insertion_m, 0.0, task.track_length_m, cols)
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
