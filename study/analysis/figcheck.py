"""The figure check: is a drawn matplotlib figure legible at the size it is printed?

It renders the figure once and looks at the text that was actually drawn (a tick label
outside the view limits is never drawn and is not checked):

- every text is at least `MIN_FONT_PT` (IEEE asks for 8 pt at column width);
- no two texts' bounding boxes overlap (`get_window_extent` on the figure's renderer),
  and none reaches outside the figure;
- on Fig. 12, the significance marks drawn (texts whose gid is `mark:<measure>/<group>`,
  set by `figures.fig12`) are exactly the stars of the p values the analysis reports,
  and no mark is drawn where the analysis ran no test (too few pairs, not testable).

`check_figure` returns the problems as sentences (empty: the figure passes);
`require_legible` raises `FigureCheckError` with all of them. `study figures` and
`study demo` run it on every figure they write; the tests run it at both widths.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager

import numpy as np
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from study.errors import StudyInputError

MIN_FONT_PT = 8.0
"""Smallest font size a printed figure may use (IEEE author guidelines)."""
OVERLAP_PX = 0.5
"""Two boxes overlap when they share more than this many pixels in both directions."""
MARK_GID = "mark:"


class FigureCheckError(StudyInputError):
    """A figure fails the legibility check; the message lists every problem."""


def stars(p: float | None) -> str:
    """The significance mark of a (Holm-corrected) p: ***, **, *, n.s.; n/a without a test."""
    if p is None or not np.isfinite(p):
        return "n/a"
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else "n.s."


@contextmanager
def _recording() -> Iterator[list[Text]]:
    """Record every `Text` drawn while open (by wrapping `Text.draw` for the duration:
    one check at a time per process, which is how the CLI and the TUI's worker run it)."""
    drawn: list[Text] = []
    original = Text.draw

    def record(self: Text, renderer) -> None:
        original(self, renderer)
        if self.get_visible() and self.get_text().strip():
            drawn.append(self)

    # matplotlib's stubs type Text.draw as Artist's (any Artist); it draws a Text
    Text.draw = record  # type: ignore[method-assign, assignment]
    try:
        yield drawn
    finally:
        Text.draw = original  # type: ignore[method-assign]


def drawn_texts(fig: Figure) -> list[Text]:
    """The non-empty texts a render of `fig` draws, in drawing order."""
    with _recording() as drawn:
        fig.canvas.draw()
    return list(dict.fromkeys(drawn))


def _describe(t: Text) -> str:
    return repr(t.get_text().replace("\n", " ")[:40])


def _overlap(a: Bbox, b: Bbox) -> bool:
    dx = min(a.x1, b.x1) - max(a.x0, b.x0)
    dy = min(a.y1, b.y1) - max(a.y0, b.y0)
    return dx > OVERLAP_PX and dy > OVERLAP_PX


def check_figure(
    fig: Figure,
    expected_marks: Mapping[str, float | None] | None = None,
    min_font_pt: float = MIN_FONT_PT,
) -> list[str]:
    """Problems of a drawn figure, one sentence each; [] when it passes.

    Parameters
    ----------
    fig
        The figure, at the size it is printed.
    expected_marks
        For Fig. 12: `"<measure>/<group>" -> p` (Holm-corrected; None where no test was
        run). Every mark drawn must be `stars(p)`, every expected mark drawn, and none
        drawn where p is None.
    min_font_pt
        Smallest font size allowed, pt.
    """
    texts = drawn_texts(fig)
    problems = []
    for t in texts:
        size_pt = float(t.get_fontsize())  # points (the stubs allow a size's name)
        if size_pt < min_font_pt - 1e-9:
            problems.append(f"text {_describe(t)} at {size_pt:g} pt < {min_font_pt:g} pt")
    # on the renderer of the draw just made (the figure's)
    boxes = [(t, t.get_window_extent()) for t in texts]
    page = fig.bbox
    for t, box in boxes:
        if (
            box.x0 < page.x0 - 1
            or box.y0 < page.y0 - 1
            or box.x1 > page.x1 + 1
            or box.y1 > page.y1 + 1
        ):
            problems.append(f"text {_describe(t)} reaches outside the figure")
    for i, (a, box_a) in enumerate(boxes):
        for b, box_b in boxes[i + 1 :]:
            if _overlap(box_a, box_b):
                problems.append(f"texts {_describe(a)} and {_describe(b)} overlap")
    if expected_marks is not None:
        problems += _check_marks(texts, expected_marks)
    return problems


def _check_marks(texts: list[Text], expected: Mapping[str, float | None]) -> list[str]:
    drawn = {}
    for t in texts:
        gid = t.get_gid() or ""
        if gid.startswith(MARK_GID):
            drawn[gid[len(MARK_GID) :]] = t.get_text()
    problems = []
    for key, p in expected.items():
        if p is None:
            if key in drawn:
                problems.append(f"mark of {key} ({drawn[key]!r}) drawn where no test was run")
            continue
        want = stars(p)
        if key not in drawn:
            problems.append(f"mark of {key} missing (expected {want!r})")
        elif drawn[key] != want:
            problems.append(f"mark of {key} is {drawn[key]!r}; the reported p gives {want!r}")
    for key in sorted(set(drawn) - set(expected)):
        problems.append(f"mark of {key} ({drawn[key]!r}) has no reported test")
    return problems


def require_legible(
    fig: Figure, name: str, expected_marks: Mapping[str, float | None] | None = None
) -> None:
    """Raise `FigureCheckError` listing every problem of `fig` (called `name`)."""
    problems = check_figure(fig, expected_marks)
    if problems:
        raise FigureCheckError(f"figure {name}: " + "; ".join(problems))
