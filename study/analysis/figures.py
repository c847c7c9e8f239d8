"""Figures for the paper, in one style: IEEE widths, embedded fonts, colour-blind-safe.

- `fig12`: per group, VO vs HV strips of participant means with paired lines and the
  significance of each test (completion time, peak proximal force, peak distal force,
  raw TLX), as the paper's Fig. 12;
- `force_traces`: one stored trial's proximal (estimated and reference) and distal
  forces over time, as Fig. 9;
- `tlx_profile`: mean rating of each NASA-TLX subscale per condition and group.

Okabe-Ito colours (Okabe & Ito 2008) and Type 42 (TrueType) fonts in PDF, so text
stays text; each plot function takes an Axes (or makes its own figure) and returns it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from db.models.tlx import TLX_SUBSCALES

WIDTHS_IN = {"single": 3.5, "double": 7.16}
"""IEEE column widths."""
OKABE_ITO = {"VO": "#D55E00", "HV": "#0072B2", "grey": "#999999"}
STYLE = {
    "font.size": 7,
    "axes.titlesize": 7,
    "axes.labelsize": 7,
    "xtick.labelsize": 6,
    "ytick.labelsize": 6,
    "legend.fontsize": 6,
    "pdf.fonttype": 42,
    "ps.fonttype": 42,
    "svg.fonttype": "none",
    "axes.spines.top": False,
    "axes.spines.right": False,
    "lines.linewidth": 0.8,
}
LABELS = {
    "completion_time_s": "completion time (s)",
    "peak_proximal_force_n": "peak proximal force (N)",
    "peak_distal_force_n": "peak distal force (N)",
    "tlx_raw": "raw NASA-TLX",
}


def _stars(p: float | None) -> str:
    if p is None or not np.isfinite(p):
        return "n/a"
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else "n.s."


def fig12(
    long: pd.DataFrame,
    comparisons: pd.DataFrame,
    width: str = "double",
    measures: Sequence[str] = tuple(LABELS),
) -> plt.Figure:
    """Per group and measure: VO and HV participant means, paired lines, Holm-corrected
    significance of the within-group test."""
    measures = [m for m in measures if m in set(long["measure"])]
    groups = list(dict.fromkeys(long["group"]))
    with plt.rc_context(STYLE):
        ncol = 2 if width == "single" else len(measures)
        nrow = int(np.ceil(len(measures) / ncol))
        fig, axes = plt.subplots(
            nrow, ncol, figsize=(WIDTHS_IN[width], 1.9 * nrow), layout="constrained",
            squeeze=False,
        )  # fmt: skip
        for ax, measure in zip(axes.ravel(), measures, strict=False):
            data = long[long["measure"] == measure]
            for gi, group in enumerate(groups):
                wide = (
                    data[data["group"] == group]
                    .pivot_table(index="participant", columns="condition", values="value")
                    .dropna()
                )
                x0 = gi * 3.0
                for _, r in wide.iterrows():
                    ax.plot([x0, x0 + 1], [r["VO"], r["HV"]], color=OKABE_ITO["grey"], lw=0.4,
                            alpha=0.6, zorder=1)  # fmt: skip
                for k, cond in enumerate(("VO", "HV")):
                    label = cond if gi == 0 else None
                    ax.scatter(np.full(len(wide), x0 + k), wide[cond], s=6,
                               color=OKABE_ITO[cond], zorder=2, label=label)  # fmt: skip
                    ax.plot([x0 + k - 0.25, x0 + k + 0.25], [wide[cond].mean()] * 2,
                            color="black", lw=1.2, zorder=3)  # fmt: skip
                row = comparisons[(comparisons["measure"] == measure)
                                  & (comparisons["group"] == group)]  # fmt: skip
                p = float(row["p_holm"].iloc[0]) if len(row) else None
                top = float(np.nanmax(wide.to_numpy())) if len(wide) else 0.0
                ax.text(x0 + 0.5, top * 1.04, _stars(p), ha="center", va="bottom", fontsize=6)
            ax.set_xticks([3.0 * g + 0.5 for g in range(len(groups))], groups)
            ax.set_ylabel(LABELS.get(measure, measure))
            ax.set_ylim(bottom=0)
            ax.margins(y=0.12)
        for ax in axes.ravel()[len(measures) :]:
            ax.set_visible(False)
        axes.ravel()[0].legend(loc="lower left", frameon=False, handletextpad=0.2)
    return fig


def force_traces(samples: pd.DataFrame, title: str = "", width: str = "single") -> plt.Figure:
    """Proximal (estimated, reference) and distal force over one trial."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(WIDTHS_IN[width], 1.8), layout="constrained")
        ax.plot(samples["t_s"], samples["proximal_force_n"], color=OKABE_ITO["grey"],
                label="proximal (ref.)")  # fmt: skip
        ax.plot(samples["t_s"], samples["proximal_force_est_n"], color=OKABE_ITO["HV"],
                label="proximal (est.)")  # fmt: skip
        ax.plot(samples["t_s"], samples["distal_force_n"], color=OKABE_ITO["VO"], label="distal")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("force (N)")
        low, high = ax.get_ylim()
        ax.set_ylim(low, high + 0.35 * (high - low))  # room for the legend above the data
        ax.legend(frameon=False, ncols=3, loc="upper left")
        if title:
            ax.set_title(title)
    return fig


def tlx_profile(tlx: pd.DataFrame, width: str = "single") -> plt.Figure:
    """Mean rating per subscale, VO vs HV (all groups pooled; 95 % CI bars)."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(WIDTHS_IN[width], 1.9), layout="constrained")
        x = np.arange(len(TLX_SUBSCALES))
        for k, cond in enumerate(("VO", "HV")):
            c = tlx[tlx["condition"] == cond]
            cols = [f"tlx_{s}" for s in TLX_SUBSCALES]
            mean = c[cols].mean().to_numpy()
            half = 1.96 * c[cols].std(ddof=1).to_numpy() / np.sqrt(max(len(c), 1))
            ax.bar(x + (k - 0.5) * 0.38, mean, 0.36, yerr=half, capsize=1.5,
                   color=OKABE_ITO[cond], label=cond, error_kw={"lw": 0.6})  # fmt: skip
        ax.set_xticks(x, [s[:4] + "." if len(s) > 6 else s for s in TLX_SUBSCALES])
        ax.set_ylabel("rating (0-100)")
        ax.set_ylim(0, 100)
        ax.legend(frameon=False, ncols=2, loc="upper right")
    return fig


def label_source(fig: plt.Figure, note: str) -> plt.Figure:
    """Write the data-source note (`DataSource.note`) into the figure, above the panels;
    nothing when the note is empty (measured data)."""
    if note:
        fig.suptitle(note, x=0.0, ha="left", fontsize=8, fontstyle="italic", color="#444444")
    return fig


def save(fig: plt.Figure, out_dir: Path, name: str, formats: Sequence[str]) -> list[Path]:
    paths = []
    with plt.rc_context(STYLE):  # the font types apply when the file is written
        for fmt in formats:
            path = out_dir / f"{name}.{fmt}"
            fig.savefig(path, dpi=300 if fmt == "png" else None)
            paths.append(path)
    plt.close(fig)
    return paths
