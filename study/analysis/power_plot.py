"""The power curve figure (same style as the paper figures)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from study.analysis.figures import STYLE, WIDTHS_IN
from study.analysis.power import PowerResult

COLORS = ("#E69F00", "#56B4E9", "#009E73", "#CC79A7")


def plot_power_curve(curve: list[tuple[float, PowerResult]]) -> plt.Figure:
    """Power against total sample size, per group and for the interaction."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(WIDTHS_IN["single"], 2.2), layout="constrained")
        totals = [sum(r.sizes.values()) for _, r in curve]
        groups = list(curve[0][1].groups)
        for color, group in zip(COLORS, groups, strict=False):
            ax.plot(totals, [r.groups[group] for _, r in curve], "o-", ms=2.5, color=color,
                    label=group)  # fmt: skip
        if curve[0][1].interaction is not None:
            ax.plot(totals, [r.interaction for _, r in curve], "s--", ms=2.5, color="black",
                    label="group x condition")  # fmt: skip
        ax.axhline(0.8, color="#999999", lw=0.6, ls=":")
        ax.set_xlabel("total participants (group sizes scaled with the design's)")
        ax.set_ylabel("power")
        ax.set_ylim(0, 1.02)
        ax.legend(frameon=False)
    return fig
