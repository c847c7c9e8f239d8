"""The power curve figure (the paper figures' style, `figures.STYLE`).

Two panels. Left: the power of each group's VO-HV test against that group's own size
(the curve scales every group with the design), one marker and line style per group so
the lines stay apart where they overlap and in grey print. Right: the group x condition
test against the total N, labelled as what it is: power when the simulated effects
differ, a type I error rate (with alpha drawn) when they are equal.

Each estimate is a share of `n_sim` simulated studies, drawn with its 95 % Monte-Carlo
interval (Wilson score, statsmodels' `proportion_confint`). The figure holds no
caption: `power_caption` states what was assumed (the effects, the VO-HV correlation,
alpha, the correction and the number of simulated studies per size), and `study power`
writes it to `captions.md` beside the figure, as the paper figures' captions are.
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from study.analysis.apa import ALPHA_SIGN, alpha_text
from study.analysis.figures import STYLE, WIDTHS_IN
from study.analysis.power import PowerResult
from study.analysis.stats import ALPHA

COLORS = ("#E69F00", "#56B4E9", "#009E73", "#CC79A7", "#0072B2", "#D55E00")
MARKERS = ("o", "s", "^", "D", "v", "P")
LINESTYLES = ("-", "--", ":", "-.", (0, (5, 1)), (0, (1, 1)))


def monte_carlo_band(rates: list[float], n_sim: int) -> tuple[np.ndarray, np.ndarray]:
    """The 95 % Wilson interval of each rate, a share of `n_sim` simulated studies."""
    # lazy: statsmodels.stats.proportion costs 10 ms at start-up
    from statsmodels.stats.proportion import proportion_confint

    hits = np.round(np.asarray(rates, dtype=float) * n_sim)
    low, high = proportion_confint(hits, n_sim, alpha=0.05, method="wilson")
    return np.asarray(low), np.asarray(high)


def power_caption(
    effects: dict[str, float], rho: float, n_sim: int, measure: str | None = None
) -> str:
    """The figure's caption, for `captions.md`: what the simulation assumed and what the
    marks and bands are."""
    shown = ", ".join(f"{g} {d:g}" for g, d in effects.items())
    return (
        f"Power of simulated studies of {measure or 'a standardised measure'}. Assumed "
        f"HV - VO effects, in standard deviations of one condition: {shown}. VO-HV "
        f"correlation {rho:g}. {ALPHA_SIGN} = {alpha_text(ALPHA)}; each group's power "
        f"with Holm's correction across the groups. {n_sim} simulated studies per size. "
        "Bands: 95 % Monte-Carlo intervals (Wilson). Dotted: power 0.8."
    )


def plot_power_curve(
    curve: list[tuple[float, PowerResult]],
    width: str = "single",
    *,
    n_sim: int,
) -> plt.Figure:
    """Per-group power against the group's n; the interaction against total N; each with
    its Monte-Carlo interval (the assumptions go to the caption, `power_caption`)."""
    first = curve[0][1]
    has_interaction = first.interaction is not None
    with plt.rc_context(STYLE):
        ncols = 2 if has_interaction else 1
        rows = 2 if (width == "single" and has_interaction) else 1
        cols = 1 if rows == 2 else ncols
        fig, axes = plt.subplots(
            rows,
            cols,
            figsize=(WIDTHS_IN[width], 2.2 * rows + 0.2),
            layout="constrained",
            squeeze=False,
        )
        ax = axes.ravel()[0]
        for k, group in enumerate(first.groups):
            sizes = [r.sizes[group] for _, r in curve]
            rates = [r.groups[group] for _, r in curve]
            low, high = monte_carlo_band(rates, n_sim)
            ax.fill_between(sizes, low, high, color=COLORS[k % 6], alpha=0.2, lw=0)
            ax.plot(
                sizes,
                rates,
                marker=MARKERS[k % 6],
                ls=LINESTYLES[k % 6],
                ms=3.5,
                color=COLORS[k % 6],
                label=group,
            )
        ax.axhline(0.8, color="#999999", lw=0.6, ls=":")
        ax.set_xlabel("participants in the group")
        ax.set_ylabel("power, VO vs HV in the group\n(Holm across groups)")
        ax.set_ylim(0, 1.02)
        ax.legend(loc="lower right")
        if has_interaction:
            ax = axes.ravel()[1]
            totals = [sum(r.sizes.values()) for _, r in curve]
            # every size of a curve with an interaction has its rate
            rates = [math.nan if r.interaction is None else r.interaction for _, r in curve]
            low, high = monte_carlo_band(rates, n_sim)
            ax.fill_between(totals, low, high, color="black", alpha=0.15, lw=0)
            if first.interaction_is_power:
                ax.plot(totals, rates, "s--", ms=3.5, color="black")
                ax.axhline(0.8, color="#999999", lw=0.6, ls=":")
                ax.set_ylabel("power, group x condition")
                ax.set_ylim(0, 1.02)
            else:
                ax.plot(totals, rates, "s--", ms=3.5, color="black", label="rejection rate")
                ax.axhline(
                    ALPHA,
                    color="#999999",
                    lw=0.6,
                    ls=":",
                    label=f"{ALPHA_SIGN} = {alpha_text(ALPHA)}",
                )
                ax.set_ylabel("type I error rate,\ngroup x condition (equal effects)")
                ax.set_ylim(0, max(0.2, *rates) * 1.1)
                ax.legend(loc="upper right")
            ax.set_xlabel("participants in all groups")
    return fig
