"""The NASA-TLX profile: mean rating of each subscale, VO vs HV, one panel per group.

Groups are not pooled (the largest group would dominate). The intervals are
within-subject 95 % confidence intervals (Cousineau 2005 with Morey's 2008
correction), the right intervals for a VO-HV comparison made on the same people: each
participant's ratings are centred on the grand mean (their own mean over the
conditions removed), and the t-based interval of the centred ratings is widened by
sqrt(J / (J - 1)) for J conditions.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from scipy.stats import t as t_dist

from db.models.tlx import TLX_SUBSCALES
from study.analysis.figures import OKABE_ITO, STYLE, WIDTHS_IN, figure_legend

CONDITIONS = ("VO", "HV")
SINGLE_MAX_IN = 4.0
"""The tallest a single-column figure may be (a column's upper part)."""
ABBREVIATIONS = {
    "mental": "MD",
    "physical": "PD",
    "temporal": "TD",
    "performance": "OP",
    "effort": "EF",
    "frustration": "FR",
}
"""The subscales' usual abbreviations (mental, physical and temporal demand, own
performance, effort, frustration): upright tick labels that fit a single column."""
NOTE = (
    "Raw ratings of the six NASA-TLX subscales: MD mental, PD physical and TD temporal "
    "demand, OP own performance, EF effort, FR frustration. Bars: mean; whiskers: 95 % "
    "within-subject CI (Cousineau-Morey). Lower is better on every subscale: "
    "performance reads 0 = perfect."
)
"""The caption (`captions.md`; the figure holds none)."""


def cousineau_morey(wide: pd.DataFrame, level: float = 0.95) -> pd.DataFrame:
    """Within-subject means and confidence intervals of one measure.

    Parameters
    ----------
    wide
        One row per participant, one column per condition (participants missing a
        condition are dropped).
    level
        Confidence level.

    Returns
    -------
    DataFrame indexed by condition: mean, half (half-width of the interval), n.
    """
    wide = wide.dropna()
    n, j = wide.shape
    # y'_ij = y_ij - mean_j(y_ij) + grand mean (Cousineau 2005)
    centred = wide.sub(wide.mean(axis=1), axis=0) + wide.to_numpy().mean()
    if n < 2 or j < 2:
        half = pd.Series(np.nan, index=wide.columns)
    else:
        # half = t(1 - alpha/2, n - 1) * SD(y') / sqrt(n) * sqrt(J / (J - 1)) (Morey 2008)
        t = float(t_dist.ppf(0.5 + level / 2, n - 1))
        half = t * centred.std(ddof=1) / math.sqrt(n) * math.sqrt(j / (j - 1))
    return pd.DataFrame({"mean": wide.mean(), "half": half, "n": n})


def tlx_profile(tlx: pd.DataFrame, width: str = "double") -> plt.Figure:
    """Per group (panel), per subscale: VO and HV mean ratings with within-subject CIs.

    `tlx` is one task's questionnaires (`frames.tlx_frame`).
    """
    groups = list(dict.fromkeys(tlx["group"]))
    with plt.rc_context(STYLE):
        rows, cols = (len(groups), 1) if width == "single" else (1, len(groups))
        # single column: stacked panels sharing the subscale axis, at most SINGLE_MAX_IN
        height = (min(0.75 * rows, 2.3) + 1.6) if width == "single" else 3.0
        fig, axes = plt.subplots(
            rows,
            cols,
            figsize=(WIDTHS_IN[width], height),
            sharey=True,
            sharex=True,
            layout="constrained",
            squeeze=False,
        )
        x = np.arange(len(TLX_SUBSCALES))
        for ax, group in zip(axes.ravel(), groups, strict=True):
            data = tlx[tlx["group"] == group]
            n = 0
            for s_i, sub in enumerate(TLX_SUBSCALES):
                wide = data.pivot_table(
                    index="participant", columns="condition", values=f"tlx_{sub}"
                )
                cm = cousineau_morey(wide.reindex(columns=list(CONDITIONS)))
                n = max(n, int(cm["n"].iloc[0]))
                for k, cond in enumerate(CONDITIONS):
                    ax.bar(
                        x[s_i] + (k - 0.5) * 0.4,
                        cm.loc[cond, "mean"],
                        0.38,
                        yerr=cm.loc[cond, "half"],
                        capsize=1.5,
                        color=OKABE_ITO[cond],
                        label=cond if s_i == 0 else None,
                        error_kw={"lw": 0.6},
                    )
            ax.set_title(f"{group} (n = {n})", pad=2)
            ax.set_ylim(0, 100)
            if width == "single":
                ax.set_yticks([0, 50, 100])
        if width == "single":  # one label for the stacked panels (each too short for it)
            fig.supylabel("rating (0-100)", fontsize=STYLE["axes.labelsize"])
        else:
            for ax in axes[:, 0]:
                ax.set_ylabel("rating (0-100)")
        for ax in axes[-1, :]:
            ax.set_xticks(x, [ABBREVIATIONS[s] for s in TLX_SUBSCALES], rotation=0)
            ax.set_xlabel("NASA-TLX subscale")
        handles, _ = axes.ravel()[0].get_legend_handles_labels()
        figure_legend(fig, handles, ncols=2)
    return fig
