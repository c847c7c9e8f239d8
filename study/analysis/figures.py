"""The paper figures' one style, and Fig. 12.

The style (`STYLE`, `WIDTHS_IN`, Okabe-Ito colours) is shared by every figure of the
project: IEEE single (3.5 in) and double (7.16 in) column widths, every text at 8 pt
(IEEE's minimum at column width; `figcheck` verifies it on the drawn figure), Type 42
(TrueType) fonts in PDF so text stays text, colour-blind-safe colours (Okabe & Ito
2008). Helpers every figure uses: `label_source` (the simulated-data note),
`figure_legend` (the legend under the panels), `jitter` (seeded, so a figure is the
same on every run) and `save`. The paper's figures (`paper.write_figures`) carry
no caption inside: each has its caption text (`fig12_caption`, ...) and
`paper.write_figures` writes them to `captions.md` beside the figures, where a paper
takes them from; the figure keeps its panels legible at column width.

- `fig12`: one task's Fig. 12: per measure, per group, VO and HV participant means
  (jittered), paired lines, group means, the Holm-corrected mark of the within-group
  test (no mark where no test was run: fewer than 3 pairs, or not testable), and the
  test under each group. Its NASA-TLX panel is the weighted score by default (the raw
  one on request), and its y-label says which. Other figures: `trace_figure` (Fig. 9)
  and `tlx_figure` (NASA-TLX profile).
"""

from __future__ import annotations

import textwrap
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeGuard

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.artist import Artist
from matplotlib.lines import Line2D

from study.analysis.figcheck import MARK_GID, stars

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

WIDTHS_IN = {"single": 3.5, "double": 7.16}
"""IEEE column widths."""
FONT_PT = 8
OKABE_ITO = {"VO": "#D55E00", "HV": "#0072B2", "grey": "#999999"}
STYLE: dict[RcKeyType, Any] = {
    "font.size": FONT_PT,
    "axes.titlesize": FONT_PT,
    "axes.labelsize": FONT_PT,
    "xtick.labelsize": FONT_PT,
    "ytick.labelsize": FONT_PT,
    "legend.fontsize": FONT_PT,
    "figure.titlesize": FONT_PT,
    "figure.labelsize": FONT_PT,
    "pdf.fonttype": 42,
    "ps.fonttype": 42,
    "svg.fonttype": "none",
    "axes.spines.top": False,
    "axes.spines.right": False,
    "lines.linewidth": 0.8,
    "legend.frameon": False,
}
LABELS = {
    "completion_time_s": "completion\ntime (s)",
    "peak_proximal_force_n": "peak proximal\nforce (N)",
    "peak_distal_force_n": "peak distal\nforce (N)",
    "tlx_weighted": "weighted NASA-TLX\n(0-100)",
}
"""Fig. 12's measures of the LCCA task and their y-labels, on two lines so that they
stay shorter than a panel is tall; other tasks' from `fig12_labels`."""
TLX_LABELS = {"weighted": LABELS["tlx_weighted"], "raw": "raw NASA-TLX\n(0-100)"}
"""The NASA-TLX panel's y-label of each score (`tlx_score`)."""
TLX_SCORES = tuple(TLX_LABELS)
"""The NASA-TLX scores Fig. 12 can show; the first is the default."""


def fig12_labels(task: str, tlx_score: str = "weighted") -> dict[str, str]:
    """Fig. 12's measures of `task` (its analysed measures and the NASA-TLX score
    `tlx_score`, weighted or raw), each with its y-label on two lines."""
    # lazy: study.protocol.tasks costs 6 ms at start-up
    from study.protocol.tasks import get_task

    out = {}
    for m in get_task(task).all_measures:
        if m.analysed:
            words = m.label.split()
            cut = max(len(words) - 1, 1)
            first, second = " ".join(words[:cut]), " ".join(words[cut:])
            unit = f" ({m.unit})" if m.unit else ""
            out[m.name] = LABELS.get(m.name, f"{first}\n{second}{unit}".strip())
    return {**out, f"tlx_{tlx_score}": TLX_LABELS[tlx_score]}


CHARS_PER_IN = 13.0
"""Characters of 8 pt text per inch of width, with room to spare (DejaVu Sans averages
about 15)."""
JITTER = 0.18
"""Half-width of the horizontal jitter of participant points, in x units (1 = VO to HV)."""


def wrap(text: str, width_in: float) -> str:
    """`text` broken into lines that fit `width_in` inches at 8 pt."""
    return "\n".join(textwrap.wrap(text, max(int(width_in * CHARS_PER_IN), 10)))


def label_source(fig: plt.Figure, note: str) -> plt.Figure:
    """Write the data-source note (`DataSource.note`) into the figure, above the panels;
    nothing when the note is empty (measured data)."""
    if note:
        fig.suptitle(
            wrap(note, fig.get_figwidth()),
            x=0.02,
            ha="left",
            fontsize=FONT_PT,
            fontstyle="italic",
            color="#444444",
        )
    return fig


def figure_legend(fig: plt.Figure, handles: Sequence[Artist], ncols: int) -> plt.Figure:
    """The figure's legend under the panels, without a caption (the paper figures'
    captions go to `captions.md`)."""
    fig.legend(
        handles=list(handles),
        loc="outside lower center",
        ncols=ncols,
        handlelength=1.5,
        columnspacing=1.0,
    )
    return fig


def jitter(n: int, key: str, half_width: float = JITTER) -> np.ndarray:
    """`n` horizontal offsets, the same for the same `key` on every run."""
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    return rng.uniform(-half_width, half_width, n)


def tested(row: pd.Series | None) -> TypeGuard[pd.Series]:
    """Whether a comparisons row holds a test with a p (not: no row, or not testable)."""
    if row is None or str(row.get("not_testable") or "") or row["test"] == "none":
        return False
    p = row.get("p_holm")
    return p is not None and bool(np.isfinite(float(p)))


def method_label(row: pd.Series | None, short: bool = False) -> str:
    """What `compare_conditions` ran, as the figure says it under the group: 'paired t',
    or 'Wilcoxon' and '(exact)' or '(asymptotic)' on two lines (narrow enough that the
    first group's label clears the y-axis); `short` (single column): 't', 'W (ex.)' or
    'W (as.)', spelled out in the caption (`SHORT_CAPTION`); 'no test' where none was
    run (too few pairs, or not testable)."""
    if not tested(row):
        return "no test"
    assert row is not None
    if row["test"] == "paired_t":
        return "t" if short else "paired t"
    if short:
        return f"W ({row['p_method'][:2]}.)"
    return f"Wilcoxon\n({row['p_method']})"


SHORT_CAPTION = (
    " Under each group: t, paired t-test; W, Wilcoxon signed-rank test, ex. exact "
    "or as. asymptotic p."
)
SINGLE_MAX_IN = 4.0
"""The tallest a single-column figure may be."""
PANEL_TITLE_CHARS = 20
"""The longest one-line panel title of the single column (a panel is 1.5 in wide);
longer labels keep their two lines."""


def _legend_handles() -> list[Line2D]:
    return [
        Line2D(
            [], [], color=OKABE_ITO["VO"], label="VO, participant", ls="none", marker="o", ms=3.5
        ),
        Line2D(
            [], [], color=OKABE_ITO["HV"], label="HV, participant", ls="none", marker="o", ms=3.5
        ),
        Line2D([], [], color=OKABE_ITO["grey"], lw=0.6, label="same participant"),
        Line2D([], [], color="black", lw=1.4, label="group mean"),
    ]


MARKS_CAPTION = (
    "Points: participant means (jittered); grey lines join a participant's two means; "
    "black bars: group means. Marks: Holm-corrected p of the test named under each "
    "group; * p < .05, ** p < .01, *** p < .001, n.s. p >= .05."
)


def _row_of(comparisons: pd.DataFrame, measure: str, group: str) -> pd.Series | None:
    rows = comparisons[(comparisons["measure"] == measure) & (comparisons["group"] == group)]
    return rows.iloc[0] if len(rows) else None


def _panel_measures(long: pd.DataFrame, measures: Sequence[str] | Mapping[str, str]) -> list[str]:
    return [m for m in measures if m in set(long["measure"])]


def fig12_caption(
    long: pd.DataFrame,
    comparisons: pd.DataFrame,
    width: str = "double",
    measures: Sequence[str] | Mapping[str, str] = tuple(LABELS),
) -> str:
    """Fig. 12's caption, for `captions.md` (the figure holds none): what the points,
    lines and marks are, the abbreviations of the single column, which NASA-TLX score
    the TLX panel shows, and each group drawn without a test and why."""
    labels = {**LABELS, **measures} if isinstance(measures, Mapping) else LABELS
    shown = _panel_measures(long, measures)
    parts = [
        "VO and HV per group and measure (HV - VO compared within each group).",
        MARKS_CAPTION + (SHORT_CAPTION if width == "single" else ""),
    ]
    for score in TLX_SCORES:
        if f"tlx_{score}" in shown:
            parts.append(f"NASA-TLX panel: the {score} score (0-100).")
    untested = []
    for measure in shown:
        name = labels.get(measure, measure).replace("\n", " ")
        for group in dict.fromkeys(long["group"]):
            row = _row_of(comparisons, measure, group)
            if row is None:
                untested.append(f"{name}, {group}: fewer than 3 complete pairs")
            elif not tested(row):
                reason = str(row.get("not_testable") or "no p")
                untested.append(f"{name}, {group}: not testable ({reason})")
    if untested:
        parts.append("No test and no mark: " + "; ".join(untested) + ".")
    return " ".join(parts)


def fig12(
    long: pd.DataFrame,
    comparisons: pd.DataFrame,
    width: str = "double",
    measures: Sequence[str] | Mapping[str, str] = tuple(LABELS),
) -> plt.Figure:
    """Fig. 12 of ONE task: per measure (panel) and group, VO and HV participant means.

    Parameters
    ----------
    long
        Participant means of one task (`frames.participant_means`): participant, group,
        condition, measure, value.
    comparisons
        `stats.compare_conditions` rows of the same task; each group's mark is the
        star of its `p_holm`, the test under it is its `test` (and `p_method`); a group
        without a test (no row, or not testable) gets no mark.
    width
        'single' (3.5 in, one column of panels) or 'double' (7.16 in, two columns).
    measures
        The panels' measures, or measure -> y-label (`fig12_labels(task)`).

    Each mark is a text with gid `mark:<measure>/<group>` (`figcheck` reads them back).
    The caption is `fig12_caption`'s, written beside the figure, not in it.
    """
    if long["task"].nunique() > 1:
        raise ValueError("fig12 draws one task; select it first (paper.draw_figures does)")
    labels = {**LABELS, **measures} if isinstance(measures, Mapping) else LABELS
    measures = _panel_measures(long, measures)
    groups = list(dict.fromkeys(long["group"]))
    single = width == "single"
    with plt.rc_context(STYLE):
        ncol = 2
        nrow = int(np.ceil(len(measures) / ncol))
        height = min(0.8 + 1.5 * nrow, SINGLE_MAX_IN) if single else 0.8 + 1.6 * nrow
        fig, axes = plt.subplots(
            nrow, ncol, figsize=(WIDTHS_IN[width], height), layout="constrained", squeeze=False
        )
        for ax, measure in zip(axes.ravel(), measures, strict=False):
            _panel(ax, long[long["measure"] == measure], comparisons, measure, groups, single)
            label = labels.get(measure, measure)
            if single:  # the label as the panel's title: the y-axis keeps its width
                one_line = label.replace("\n", " ")
                fits = len(one_line) <= PANEL_TITLE_CHARS
                ax.set_title(one_line if fits else label, pad=2)
            else:
                ax.set_ylabel(label)
        for ax in axes.ravel()[len(measures) :]:
            ax.set_visible(False)
        figure_legend(fig, _legend_handles(), ncols=2 if single else 4)
    return fig


def _panel(
    ax: plt.Axes,
    data: pd.DataFrame,
    comparisons: pd.DataFrame,
    measure: str,
    groups: list[str],
    short: bool = False,
) -> plt.Axes:
    ticks, top = [], 0.0
    for gi, group in enumerate(groups):
        wide = (
            data[data["group"] == group]
            .pivot_table(index="participant", columns="condition", values="value")
            .reindex(columns=["VO", "HV"])
            .dropna()
        )
        x0 = gi * 3.0
        dx = {c: jitter(len(wide), f"{measure}/{group}/{c}") for c in ("VO", "HV")}
        for i, (_, r) in enumerate(wide.iterrows()):
            ax.plot(
                [x0 + dx["VO"][i], x0 + 1 + dx["HV"][i]],
                [r["VO"], r["HV"]],
                color=OKABE_ITO["grey"],
                lw=0.4,
                alpha=0.7,
                zorder=1,
            )
        for k, cond in enumerate(("VO", "HV")):
            ax.scatter(
                x0 + k + dx[cond], wide[cond], s=9, color=OKABE_ITO[cond], zorder=2, linewidths=0
            )
            if len(wide):
                ax.plot(
                    [x0 + k - 0.3, x0 + k + 0.3],
                    [wide[cond].mean()] * 2,
                    color="black",
                    lw=1.4,
                    zorder=3,
                )
        row = _row_of(comparisons, measure, group)
        high = float(np.nanmax(wide.to_numpy())) if len(wide) else 0.0
        top = max(top, high)
        if tested(row):  # no mark where no test was run
            assert row is not None
            ax.annotate(
                stars(float(row["p_holm"])),
                (x0 + 0.5, high),
                xytext=(0, 3),
                textcoords="offset points",
                ha="center",
                va="bottom",
                gid=f"{MARK_GID}{measure}/{group}",
            )
        ticks.append((x0 + 0.5, f"{group}\n{method_label(row, short)}"))
    ax.set_xticks([t for t, _ in ticks], [label for _, label in ticks], rotation=0)
    ax.tick_params(axis="x", length=0)
    ax.set_xlim(-0.6, 3.0 * len(groups) - 1.4)
    ax.set_ylim(0, (top or 1.0) * 1.3)
    return ax


def freeze_layout(fig: plt.Figure) -> None:
    """Lay `fig` out once (its layout engine, at the figure's own dpi: the layout the
    figure check measures) and keep that layout: each format written after this draws
    the same positions instead of laying the figure out again (a constrained layout per
    format cost more than drawing it)."""
    engine = fig.get_layout_engine()
    if engine is None or not hasattr(engine, "execute"):
        return
    engine.execute(fig)
    fig.set_layout_engine("none")


def figure_of(ax: plt.Axes) -> plt.Figure:
    """The figure `ax` is drawn in (the figures here have no subfigures)."""
    fig = ax.get_figure()
    if not isinstance(fig, plt.Figure):  # pragma: no cover - a subfigure's or a detached axes
        raise TypeError(f"axes {ax!r} is not drawn in a figure of its own")
    return fig


def save(fig: plt.Figure, out_dir: Path, name: str, formats: Sequence[str]) -> list[Path]:
    paths = []
    with plt.rc_context(STYLE):  # the font types apply when the file is written
        freeze_layout(fig)
        for fmt in formats:
            path = out_dir / f"{name}.{fmt}"
            fig.savefig(path, dpi=300 if fmt == "png" else None)
            paths.append(path)
    plt.close(fig)
    return paths
