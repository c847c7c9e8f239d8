"""The LCCA task's live scene: the phantom in its frontal (x-z) plane with the
guidewire's tip, drawn in Braille (`study.tui.live_view.BrailleCanvas`), 2 x 4 dots per
terminal cell, so the aortic arch and its three branches keep their shape at 80 x 24.
Terminal cells are about twice as tall as wide, which makes Braille dots about square,
so one scale serves both axes. The view frames the arch and the branches (the straight
20 cm access run below them is cut, with the tip's distance to the arch written
instead). The vessels are drawn once per size; each redraw adds only the tip. `VIEW` is
the LCCA task's view on the run screen (`study.tui.task_views`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from rich.segment import Segment
from rich.style import Style
from rich.text import Text
from textual.geometry import Region
from textual.strip import Strip
from textual.widget import Widget

from study.protocol.tasks import LiveTrace, Task
from study.tui.live_view import TARGET_STYLE, TIP_STYLE, BrailleCanvas
from study.tui.task_views import LiveView, register_view
from study.tui.trial_runner import LiveFrame
from teleop_core.phantom.anatomy import STEP_M, ArchAnatomy, build_paths

MARGIN_M = 0.008
"""Space around the arch and branches in the frame."""
TOP_ABOVE_ARCH_M = 0.06
"""How much of the branches above the arch's top the frame shows (the target depth is
30 mm past the LCCA's ostium)."""


class PhantomFrame:
    """Maps the phantom's x-z plane to dots and draws its centrelines.

    Built from `teleop_core.phantom.anatomy` (numpy only) rather than `LccaPhantom`,
    whose module compiles the phantom's kernel: the view must not wait for that.
    """

    def __init__(self, anatomy: ArchAnatomy, cols: int, rows: int) -> None:
        self.cols, self.rows = cols, rows
        geometry, meta = build_paths(anatomy)
        # as LccaPhantom.centreline: path p runs to meta[p]["end"]
        self.paths = [
            geometry[p, : round(m["end"] / STEP_M) + 1][:, [0, 2]] for p, m in enumerate(meta)
        ]
        # from the ascending aorta's end (the lowest point of the arch's side) to a little
        # above the target depth in the branches
        bottom = anatomy.descending_length_m - anatomy.ascending_length_m - 0.005
        top = anatomy.descending_length_m + anatomy.arch_radius_m + TOP_ABOVE_ARCH_M
        pts = np.concatenate([p[(p[:, 1] >= bottom) & (p[:, 1] <= top)] for p in self.paths])
        lo, hi = pts.min(axis=0) - MARGIN_M, pts.max(axis=0) + MARGIN_M
        # one scale for both axes (Braille dots are about square)
        scale = min((2 * cols - 1) / (hi[0] - lo[0]), (4 * rows - 1) / (hi[1] - lo[1]))
        self.scale = scale
        self.lo = lo
        self.z_bottom = lo[1]
        self.x_pad = ((2 * cols - 1) - scale * (hi[0] - lo[0])) / 2
        names = [b.name for b in anatomy.branches]
        self.target_path = names.index(anatomy.target) + 1
        self.base = BrailleCanvas(cols, rows)
        for k, path in enumerate(self.paths):
            style = TARGET_STYLE if k == self.target_path else ""
            for x, z in path:
                if z >= self.z_bottom:
                    self.base.dot(*self.to_dot(x, z), style)

    def to_dot(self, x_m: float, z_m: float) -> tuple[int, int]:
        dx = round(self.x_pad + (x_m - self.lo[0]) * self.scale)
        dy = round(4 * self.rows - 1 - (z_m - self.lo[1]) * self.scale)
        return dx, dy

    def tip_dots(self, frame: LiveFrame) -> tuple[list[tuple[int, int]], float | None]:
        """The tip's 2 x 2 dot blob, and how far below the frame it is (m), if it is."""
        x, z = frame.tip_xz_m
        below = None
        if z < self.z_bottom:
            below, z = self.z_bottom - z, self.z_bottom
        dx, dy = self.to_dot(x, z)
        return [(dx + ox - 1, dy + oy - 1) for ox, oy in ((0, 0), (1, 0), (0, 1), (1, 1))], below

    def draw(self, frame: LiveFrame | None) -> Text:
        """The whole view as Text (snapshots of a frame; the widget draws line by line)."""
        canvas = self.base.copy()
        below = None
        if frame is not None:
            dots, below = self.tip_dots(frame)
            for x, y in dots:
                canvas.dot(x, y, TIP_STYLE)
        text = canvas.to_text()
        if below is not None:
            text.append(f"\n tip {below * 1000:.0f} mm below the frame", TIP_STYLE)
        return text


class PhantomView(Widget):
    """The phantom and the tip, drawn line by line (Textual's line API).

    The vessels' lines are rendered once per size; a new frame re-renders and refreshes
    only the one or two lines the tip leaves and the ones it enters, which keeps the
    live view's redraws cheap at any terminal size.
    """

    DEFAULT_CSS = """
    PhantomView { width: 1fr; height: 1fr; min-height: 6; background: $surface; }
    """

    def __init__(self, anatomy: ArchAnatomy | None = None, **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self.anatomy = anatomy or ArchAnatomy()
        self._frame: LiveFrame | None = None
        self._layout: PhantomFrame | None = None
        self._base: list[Strip] = []
        self._overlay: dict[int, Strip] = {}

    def _ensure_layout(self) -> PhantomFrame:
        cols, rows = max(self.size.width, 4), max(self.size.height - 1, 3)
        if self._layout is None or (self._layout.cols, self._layout.rows) != (cols, rows):
            self._layout = PhantomFrame(self.anatomy, cols, rows)
            canvas = self._layout.base
            self._base = [Strip(canvas.row_segments(r), cols) for r in range(rows)]
            self._base.append(Strip.blank(cols))
            self._overlay = self._lines_for(self._frame)
        return self._layout

    def _lines_for(self, frame: LiveFrame | None) -> dict[int, Strip]:
        """The lines that differ from the vessels' drawing: the tip's, the note below."""
        layout = self._layout
        if frame is None or layout is None:
            return {}
        dots, below = layout.tip_dots(frame)
        lines: dict[int, Strip] = {}
        for row in sorted({y // 4 for _, y in dots if 0 <= y < 4 * layout.rows}):
            canvas = BrailleCanvas(layout.cols, 1)
            canvas.bits[0], canvas.style[0] = layout.base.bits[row], layout.base.style[row]
            canvas.bits, canvas.style = canvas.bits.copy(), canvas.style.copy()
            for x, y in dots:
                if y // 4 == row:
                    canvas.dot(x, y % 4, TIP_STYLE)
            lines[row] = Strip(canvas.row_segments(0), layout.cols)
        if below is not None:
            note = f" tip {below * 1000:.0f} mm below the frame"[: layout.cols]
            lines[layout.rows] = Strip([Segment(note, Style.parse(TIP_STYLE))]).extend_cell_length(
                layout.cols
            )
        return lines

    def update_frame(self, frame: LiveFrame | None) -> None:
        self._frame = frame
        if self._layout is None:
            self.refresh()
            return
        old, self._overlay = self._overlay, self._lines_for(frame)
        width = self.size.width
        for y in set(old) | set(self._overlay):
            if old.get(y) != self._overlay.get(y):
                self.refresh(Region(0, y, width, 1))

    def render_line(self, y: int) -> Strip:
        self._ensure_layout()
        if y in self._overlay:
            return self._overlay[y]
        return self._base[y] if y < len(self._base) else Strip.blank(self.size.width)


def lcca_lines(task: Task, values: Mapping[str, float], condition: str | None) -> list[str]:
    """The readout: the vessel, insertion, roll, the dial and the torque on the hand."""
    # VO renders no force on the dial: the stored torque is the return spring's and
    # the model's, none of it felt as feedback
    torque = (
        "torque on the hand: none (VO, no haptic feedback)"
        if condition == "VO"
        else f"torque on the hand {values['dial_torque_n_m'] * 1000:+5.1f} mN m"
    )
    return [
        f"tip in {task.regions[int(values['branch'])]}, inserted "
        f"{values['insertion_m'] * 1000:5.0f} mm",
        f"rotation {values['rotation_rad']:+5.2f} rad",
        f"dial {values['dial_angle_rad']:+5.2f} rad",
        torque,
    ]


VIEW = register_view(
    "lcca",
    LiveView(
        traces=(
            LiveTrace("proximal_force_n", "proximal", 2.0),
            LiveTrace("distal_force_n", "distal", 1.0),
        ),
        scene=PhantomView,
        scene_title="LCCA phantom (frontal)",
        key_hints="↑↓ dial ←→ rotate space let go e end",
        lines=lcca_lines,
    ),
)
