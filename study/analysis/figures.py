"""The paper figures' one style, and Fig. 12.

The style (`STYLE`, `WIDTHS_IN`, Okabe-Ito colours) is shared by every figure of the
project: IEEE single (3.5 in) and double (7.16 in) column widths, every text at 8 pt
(IEEE's minimum at column width; `figcheck` verifies it on the drawn figure), Type 42
(TrueType) fonts in PDF so text stays text, colour-blind-safe colours (Okabe & Ito
2008). Helpers every figure uses: `label_source` (the simulated-data note),
`figure_key` (the legend under the panels, its title the caption: sign convention,
interval method), `jitter`
(seeded, so a figure is the same on every run) and `save`.

- `fig12`: one task's Fig. 12: per measure, per group, VO and HV participant means
  (jittered), paired lines, group means, the Holm-corrected mark of the within-group
  test, and the test under each group. Other figures: `trace_figure` (Fig. 9) and
  `tlx_figure` (NASA-TLX profile).
"""

from __future__ import annotations

import textwrap
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.artist import Artist
from matplotlib.lines import Line2D

from study.analysis.figcheck import MARK_GID, stars

WIDTHS_IN = {"single": 3.5, "double": 7.16}
"""IEEE column widths."""
FONT_PT = 8
OKABE_ITO = {"VO": "#D55E00", "HV": "#0072B2", "grey": "#999999"}
STYLE = {
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
    "tlx_raw": "raw NASA-TLX\n(0-100)",
}
"""Fig. 12's measures of the LCCA task and their y-labels, on two lines so that they
stay shorter than a panel is tall; other tasks' from `fig12_labels`."""


def fig12_labels(task: str) -> dict[str, str]:
    """Fig. 12's measures of `task` (its analysed measures and the raw NASA-TLX), each
    with its y-label on two lines."""
    from study.protocol.tasks import get_task

    out = {}
    for m in get_task(task).all_measures:
        if m.analysed:
            words = m.label.split()
            cut = max(len(words) - 1, 1)
            first, second = " ".join(words[:cut]), " ".join(words[cut:])
            unit = f" ({m.unit})" if m.unit else ""
            out[m.name] = LABELS.get(m.name, f"{first}\n{second}{unit}".strip())
    return {**out, "tlx_raw": LABELS["tlx_raw"]}


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


def figure_key(fig: plt.Figure, handles: Sequence[Artist], caption: str, ncols: int) -> plt.Figure:
    """The figure's legend under the panels, with `caption` (sign convention, what the
    marks and bars are) as its title, wrapped to fit: one artist, so the layout keeps it
    clear of the data-source note above the panels."""
    fig.legend(
        handles=list(handles),
        loc="outside lower center",
        ncols=ncols,
        title=wrap(caption, fig.get_figwidth()),
        title_fontsize=FONT_PT,
        handlelength=1.5,
        columnspacing=1.0,
    )
    return fig


def jitter(n: int, key: str, half_width: float = JITTER) -> np.ndarray:
    """`n` horizontal offsets, the same for the same `key` on every run."""
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    return rng.uniform(-half_width, half_width, n)


def method_label(row: pd.Series | None, short: bool = False) -> str:
    """What `compare_conditions` ran, as the figure says it under the group: 'paired t',
    or 'Wilcoxon' and '(exact)' or '(asymptotic)' on two lines (narrow enough that the
    first group's label clears the y-axis); `short` (single column): 't', 'W (ex.)' or
    'W (as.)', spelled out in the caption (`SHORT_CAPTION`)."""
    if row is None:
        return "no test"
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


def _legend_handles() -> list[Line2D]:
    point = {"ls": "none", "marker": "o", "ms": 3.5}
    return [
        Line2D([], [], color=OKABE_ITO["VO"], label="VO, participant", **point),
        Line2D([], [], color=OKABE_ITO["HV"], label="HV, participant", **point),
        Line2D([], [], color=OKABE_ITO["grey"], lw=0.6, label="same participant"),
        Line2D([], [], color="black", lw=1.4, label="group mean"),
    ]


_NB = "\u00a0"  # no line break inside a mark's threshold
MARKS_CAPTION = (
    "Points: participant means (jittered). Marks: Holm-corrected p of the test named "
    "under each group; "
    + ", ".join(f"{m}{_NB}<{_NB}{t}" for m, t in (("*", ".05"), ("**", ".01"), ("***", ".001")))
    + f", n.s.{_NB}≥{_NB}.05."
)


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
        star of its `p_holm`, the test under it is its `test` (and `p_method`).
    width
        'single' (3.5 in, panels stacked) or 'double' (7.16 in, two columns).
    measures
        The panels' measures, or measure -> y-label (`fig12_labels(task)`).

    Each mark is a text with gid `mark:<measure>/<group>` (`figcheck` reads them back).
    """
    if long["task"].nunique() > 1:
        raise ValueError("fig12 draws one task; select it first (paper.draw_figures does)")
    labels = {**LABELS, **measures} if isinstance(measures, Mapping) else LABELS
    measures = [m for m in measures if m in set(long["measure"])]
    groups = list(dict.fromkeys(long["group"]))
    single = width == "single"
    with plt.rc_context(STYLE):
        ncol = 2  # single column too: four stacked panels were 7.2 in tall
        nrow = int(np.ceil(len(measures) / ncol))
        height = min(1.6 + 1.2 * nrow, SINGLE_MAX_IN) if single else 1.2 + 1.5 * nrow
        fig, axes = plt.subplots(
            nrow, ncol, figsize=(WIDTHS_IN[width], height), layout="constrained", squeeze=False
        )
        for ax, measure in zip(axes.ravel(), measures, strict=False):
            _panel(ax, long[long["measure"] == measure], comparisons, measure, groups, single)
            label = labels.get(measure, measure)
            if single:  # lines of at most 10 characters: no taller than the short panels
                label = "\n".join(
                    textwrap.wrap(label.replace("\n", " "), 10, break_on_hyphens=False)
                )
            ax.set_ylabel(label)
        for ax in axes.ravel()[len(measures) :]:
            ax.set_visible(False)
        untested = any(
            not len(comparisons[(comparisons["measure"] == m) & (comparisons["group"] == g)])
            for m in measures
            for g in groups
        )
        caption = (
            MARKS_CAPTION
            + (SHORT_CAPTION if single else "")
            + (" n/a: no test (fewer than 3 complete pairs)." if untested else "")
        )
        figure_key(fig, _legend_handles(), caption, ncols=2 if single else 4)
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
        rows = comparisons[(comparisons["measure"] == measure) & (comparisons["group"] == group)]
        row = rows.iloc[0] if len(rows) else None
        p = float(row["p_holm"]) if row is not None else None
        high = float(np.nanmax(wide.to_numpy())) if len(wide) else 0.0
        top = max(top, high)
        ax.annotate(
            stars(p),
            (x0 + 0.5, high),
            xytext=(0, 3),
            textcoords="offset points",
            ha="center",
            va="bottom",
            gid=f"{MARK_GID}{measure}/{group}",
        )
        ticks.append((x0 + 0.5, f"{group}\n{method_label(row, short)}"))
    # single column: the panels are too narrow for the labels side by side; upright
    ax.set_xticks([t for t, _ in ticks], [label for _, label in ticks], rotation=90 if short else 0)
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
