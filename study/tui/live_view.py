"""The live view of a running trial: the phantom with the guidewire's tip, and force gauges.

The phantom is drawn in its frontal (x-z) plane with Braille characters, 2 x 4 dots per
terminal cell, so the aortic arch and its three branches keep their shape at 80 x 24.
Terminal cells are about twice as tall as wide, which makes Braille dots about square,
so one scale serves both axes. The view frames the arch and the branches (the straight
20 cm access run below them is cut, with the tip's distance to the arch written instead).
The vessels are drawn once per size; each redraw adds only the tip.

A NOTES trial has no vessels to draw: `notes_scene` shows the scope's depth along the
canal (introitus, posterior fornix, peritoneal cavity, target) and its roll against the
target roll, one character per step, redrawn whole at each frame (a few short lines).

Colours are from the Okabe-Ito palette (`study.analysis.figures`), which stays readable
on dark and light backgrounds; the vessels are drawn in the theme's dimmed foreground.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from rich.segment import Segment
from rich.style import Style
from rich.text import Text
from textual.geometry import Region
from textual.strip import Strip
from textual.widget import Widget

from study.tui.trial_runner import LiveFrame
from teleop_core.phantom.anatomy import STEP_M, ArchAnatomy, build_paths

TIP_STYLE = "bold #D55E00"
TARGET_STYLE = "#009E73"
BRAILLE_BASE = 0x2800
_DOT_BITS = ((0x01, 0x08), (0x02, 0x10), (0x04, 0x20), (0x40, 0x80))
"""Bit of the Braille dot in row r (0-3, top down) and column c (0-1) of a cell."""
MARGIN_M = 0.008
"""Space around the arch and branches in the frame."""
TOP_ABOVE_ARCH_M = 0.06
"""How much of the branches above the arch's top the frame shows (the target depth is
30 mm past the LCCA's ostium)."""


@functools.cache
def _style(spec: str) -> Style:
    return Style.parse(spec)


class BrailleCanvas:
    """Dots on a grid of `cols` x `rows` cells, each dot tagged with a style."""

    def __init__(self, cols: int, rows: int) -> None:
        self.cols, self.rows = cols, rows
        self.bits = np.zeros((rows, cols), dtype=np.int32)
        self.style = np.full((rows, cols), "", dtype=object)

    def dot(self, x: int, y: int, style: str = "") -> None:
        """Set the dot at column x (0..2 cols-1) and row y (0..4 rows-1, top down)."""
        if 0 <= x < 2 * self.cols and 0 <= y < 4 * self.rows:
            r, c = y // 4, x // 2
            self.bits[r, c] |= _DOT_BITS[y % 4][x % 2]
            if style:
                self.style[r, c] = style

    def copy(self) -> BrailleCanvas:
        out = BrailleCanvas(self.cols, self.rows)
        out.bits, out.style = self.bits.copy(), self.style.copy()
        return out

    def row_segments(self, r: int, base_style: str = "dim") -> list[Segment]:
        """Row r as segments, one per run of equally styled cells."""
        chars = [chr(BRAILLE_BASE + int(b)) if b else " " for b in self.bits[r]]
        styles = [st or base_style for st in self.style[r]]
        out, start = [], 0
        for c in range(1, self.cols + 1):
            if c == self.cols or styles[c] != styles[start]:
                out.append(Segment("".join(chars[start:c]), _style(styles[start])))
                start = c
        return out

    def to_text(self, base_style: str = "dim") -> Text:
        """The canvas as Text, one span per run of equally styled cells (a span per cell
        makes the terminal's compositor, not this code, the slow part)."""
        text = Text(no_wrap=True, overflow="crop")
        for r in range(self.rows):
            chars = [chr(BRAILLE_BASE + int(b)) if b else " " for b in self.bits[r]]
            styles = [st or base_style for st in self.style[r]]
            start = 0
            for c in range(1, self.cols + 1):
                if c == self.cols or styles[c] != styles[start]:
                    text.append("".join(chars[start:c]), styles[start])
                    start = c
            if r < self.rows - 1:
                text.append("\n")
        return text


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
            lines[layout.rows] = Strip([Segment(note, _style(TIP_STYLE))]).extend_cell_length(
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


def gauge(
    label: str, value: float, full_scale: float, width: int, unit: str = "N",
    magnitude: bool = False,
) -> Text:  # fmt: skip
    """`label  0.53 N  ██████░░░░` with the bar filled to value / full_scale (with
    `magnitude`, to |value| / full_scale, the number keeping its sign)."""
    level = abs(value) if magnitude else value
    filled = 0 if not math.isfinite(level) else round(width * min(max(level, 0) / full_scale, 1))
    text = Text(no_wrap=True)
    text.append(
        f"{label:<9}{value:+6.2f} {unit} " if magnitude else f"{label:<9}{value:6.2f} {unit} "
    )
    style = TIP_STYLE if level > 0.8 * full_scale else "bold"
    text.append("█" * filled, style)
    text.append("░" * (width - filled), "dim")
    return text


SPARK = "▁▂▃▄▅▆▇█"


def sparkline(values: tuple[float, ...], width: int, full_scale: float) -> str:
    """The last values as one line of block characters, each the maximum of its bin."""
    if not values:
        return ""
    n = min(width, len(values))
    step = len(values) / n
    bins = [max(values[int(k * step) : max(int((k + 1) * step), int(k * step) + 1)])
            for k in range(n)]  # fmt: skip
    top = len(SPARK) - 1
    return "".join(SPARK[min(max(round(top * v / full_scale), 0), top)] for v in bins)


class LiveReadout(Widget):
    """Timer, status, the two force gauges with their recent history, the dial: one widget,
    so a redraw renders one text block and changes no layout."""

    DEFAULT_CSS = """
    LiveReadout { width: 38; height: 1fr; }
    """

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self._text = Text()

    def show(self, text: Text) -> None:
        self._text = text
        self.refresh()

    def render(self) -> Text:
        return self._text
