"""The fit's figure: observed vs simulated summaries per group, condition and measure.

One row per measure, one column per VO, HV and HV - VO (the analysis's sign); in each
panel the groups along x, and for each group three marks with 95 % intervals: the
observed participants' mean (bootstrap over participants), the people simulated from
the fitted model (the same; each person from one of the fit's bootstrap replicates, so
the interval holds the fit's uncertainty too), and the emulator's prediction (the fit's
bootstrap). A condition's mean of a positive measure has its interval on the log scale
(above zero). The caption says what the data were and that the simulated marks are
simulated.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

from study.analysis.figures import FONT_PT, STYLE, WIDTHS_IN, wrap
from study.analysis.participant_fit.summaries import CONDITIONS, DIFFERENCE
from study.protocol.tasks import measure_named

SOURCES = {
    "observed": ("observed", "#000000", "o"),
    "simulated": ("simulated from the fit", "#0072B2", "s"),
    "model": ("the fitted model (emulator + discrepancy)", "#D55E00", "^"),
}
COLUMNS = CONDITIONS


def fit_figure(table: pd.DataFrame, note: str) -> plt.Figure:
    """`table`: the fit's summaries (group, measure, condition, source, mean, ci_low,
    ci_high); `note`: what the data were, written under the title."""
    measures = list(dict.fromkeys(table["measure"]))
    groups = list(dict.fromkeys(table["group"]))
    with plt.rc_context(STYLE):
        size = (WIDTHS_IN["double"], 1.9 * len(measures) + 0.9)
        fig, axes = plt.subplots(len(measures), len(COLUMNS), squeeze=False, figsize=size)
        for i, m in enumerate(measures):
            measure = measure_named(m)
            label = measure.axis_label if measure is not None else m
            for j, column in enumerate(COLUMNS):
                ax = axes[i][j]
                for k, (source, (_, colour, marker)) in enumerate(SOURCES.items()):
                    rows = table[
                        (table["measure"] == m)
                        & (table["condition"] == column)
                        & (table["source"] == source)
                    ].set_index("group")
                    rows = rows.reindex(groups)
                    x = [g + (k - 1) * 0.22 for g in range(len(groups))]
                    # the interval as drawn, the estimate as a marker: a bootstrap
                    # percentile interval need not hold the point estimate (the model's
                    # prediction at the best fit may lie outside its replicates')
                    ax.vlines(x, rows["ci_low"], rows["ci_high"], color=colour, lw=0.8)
                    for edge in ("ci_low", "ci_high"):
                        ax.plot(x, rows[edge], "_", color=colour, ms=4, mew=0.8)
                    ax.plot(x, rows["mean"], marker, color=colour, ms=3.5, ls="")
                if column == DIFFERENCE:
                    ax.axhline(0.0, color="#999999", lw=0.5)
                ax.set_xticks(range(len(groups)), groups)
                ax.set_xlim(-0.6, len(groups) - 0.4)
                if i == 0:
                    ax.set_title(column if column != DIFFERENCE else "HV - VO")
                if j == 0:
                    ax.set_ylabel(label)
        handles = [
            plt.Line2D([], [], color=c, marker=mk, ls="", ms=4) for _, c, mk in SOURCES.values()
        ]
        fig.legend(
            handles,
            [lab for lab, _, _ in SOURCES.values()],
            loc="lower center",
            ncol=3,
            fontsize=FONT_PT,
            frameon=False,
        )
        fig.suptitle(
            wrap(note, WIDTHS_IN["double"]),
            x=0.02,
            ha="left",
            fontsize=FONT_PT,
            fontstyle="italic",
            color="#444444",
        )
        fig.tight_layout(rect=(0, 0.05, 1, 0.95))
    return fig
