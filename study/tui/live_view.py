"""What every task's live view shares: a Braille canvas (`BrailleCanvas`, 2 x 4 dots per
terminal cell, on which the LCCA task's phantom is drawn: `study.tui.scene_lcca`), the
force gauges and their histories (`gauge`, `sparkline`, `LiveReadout`). The scene beside
the readout is the task's view's own (`study.tui.task_views.LiveView.scene`), or the
insertion along a track (`study.tui.scenes`).

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
from textual.widget import Widget

TIP_STYLE = "bold #D55E00"
TARGET_STYLE = "#009E73"
BRAILLE_BASE = 0x2800
_DOT_BITS = ((0x01, 0x08), (0x02, 0x10), (0x04, 0x20), (0x40, 0x80))
"""Bit of the Braille dot in row r (0-3, top down) and column c (0-1) of a cell."""


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


def gauge(
    label: str,
    value: float,
    full_scale: float,
    width: int,
    unit: str = "N",
    magnitude: bool = False,
) -> Text:
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
    bins = [
        max(values[int(k * step) : max(int((k + 1) * step), int(k * step) + 1)]) for k in range(n)
    ]
    top = len(SPARK) - 1
    return "".join(SPARK[min(max(round(top * v / full_scale), 0), top)] for v in bins)


class LiveReadout(Widget):
    """Timer, status, the two force gauges with their recent history, the dial: one widget,
    so a redraw renders one text block and changes no layout."""

    DEFAULT_CSS = """
    LiveReadout { width: 38; height: 1fr; padding-bottom: 1; }
    """

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self._text = Text()

    def show(self, text: Text) -> None:
        self._text = text
        self.refresh()

    def render(self) -> Text:
        return self._text
