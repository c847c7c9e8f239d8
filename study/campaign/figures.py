"""Figures of a campaign: power, and the standardised effect, against each swept factor.

One figure per factor and kind (`power_<factor>`, `effect_<factor>`): a panel per
measure, a line per group (Okabe-Ito colours, the paper figures' style), with the
Monte-Carlo 95 % interval as a band. When other factors are swept too, each of their
combinations gets its own row of panels. A campaign with no factor draws one figure
of each kind against the groups. Every figure's title says what it plots (`plotted`:
power or the effect, per group, against the swept factor or at the one design every
factor's single value makes), then the campaign's name, which may promise more than a
small campaign draws, and that it shows simulated participants.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

from study.analysis.figures import STYLE, WIDTHS_IN, save

GROUP_COLORS = ("#E69F00", "#0072B2", "#009E73", "#CC79A7", "#D55E00")
MARKERS = ("o", "s", "^", "D", "v")
FACTOR_LABELS = {
    "haptic_gain": "haptic gain G_h (N m/N)",
    "link_delay_ms": "link delay, one way (ms)",
    "link_jitter_ms": "link jitter (ms)",
    "link_loss": "packet loss",
    "group_scale": "group size scale",
}


def _measure_label(name: str) -> str:
    """The task's label of a measure (`study.protocol.tasks`), or its name."""
    # lazy: study.protocol.tasks costs 7 ms at start-up
    from study.protocol.tasks import measure_named

    measure = measure_named(name)
    return measure.label if measure is not None else name


SIMULATED_NOTE = "simulated participants: a simulation campaign, not measured data"


def _rows(summary: pd.DataFrame, factors: list[str], x: str) -> list[tuple[str, pd.DataFrame]]:
    others = [f for f in factors if f != x and summary[f].nunique() > 1]
    if not others:
        return [("", summary)]
    out = []
    for values in itertools.product(*(list(dict.fromkeys(summary[f])) for f in others)):
        mask = pd.Series(True, index=summary.index)
        for f, v in zip(others, values, strict=True):
            mask &= summary[f] == v
        out.append(
            (", ".join(f"{f} {v:g}" for f, v in zip(others, values, strict=True)), summary[mask])
        )
    return out


KINDS = {
    "power": "Power of HV vs VO (p < .05) per group",
    "effect": "Effect of HV vs VO (Hedges' g_av, HV - VO) per group",
}


def plotted(summary: pd.DataFrame, factors: list[str], x: str | None, kind: str) -> str:
    """What a figure plots, in words: `KINDS[kind]`, against factor `x` (its values
    named when few), or at the single setting of the factors and group sizes drawn."""
    fixed = [f for f in factors if f != x and summary[f].nunique() == 1]
    at = ", ".join(f"{f} {summary[f].iloc[0]:g}" for f in fixed)
    if x:
        values = list(dict.fromkeys(summary[x]))
        return f"{KINDS[kind]} against {FACTOR_LABELS.get(x, x)} ({len(values)} values)" + (
            f", at {at}" if at else ""
        )
    per_group = summary.groupby("group", sort=False)["n"].first()
    sizes = ", ".join(f"{g} {int(n)}" for g, n in per_group.items())
    return f"{KINDS[kind]} at one sample size ({sizes}" + (f"; {at})" if at else ")")


def plot_factor(
    summary: pd.DataFrame, factors: list[str], x: str | None, kind: str, title: str
) -> plt.Figure:
    """Power (kind 'power') or mean effect ('effect') against factor `x` (None: groups)."""
    rows = _rows(summary, factors, x) if x else [("", summary)]
    groups = list(dict.fromkeys(summary["group"]))
    measures = list(dict.fromkeys(summary["measure"]))
    y, low, high = (
        ("power", "power_ci_low", "power_ci_high")
        if kind == "power"
        else ("effect_mean", "effect_ci_low", "effect_ci_high")
    )
    with plt.rc_context(
        {
            **STYLE,
            "font.size": 8,
            "axes.titlesize": 8,
            "axes.labelsize": 8,
            "xtick.labelsize": 8,
            "ytick.labelsize": 8,
            "legend.fontsize": 8,
        }
    ):
        fig, axes = plt.subplots(
            len(rows),
            len(measures),
            figsize=(WIDTHS_IN["double"], 0.6 + 1.9 * len(rows)),
            squeeze=False,
            sharex=True,
            sharey=kind == "power",
            layout="constrained",
        )
        for r, (label, part) in enumerate(rows):
            for c, measure in enumerate(measures):
                ax = axes[r][c]
                for k, group in enumerate(groups):
                    d = part[(part["measure"] == measure) & (part["group"] == group)]
                    xs = d[x].to_numpy() if x else [k] * len(d)
                    color = GROUP_COLORS[k % len(GROUP_COLORS)]
                    sizes = "/".join(map(str, dict.fromkeys(d["n"])))
                    ax.plot(
                        xs,
                        d[y],
                        marker=MARKERS[k % len(MARKERS)],
                        ms=3,
                        color=color,
                        label=f"{group} (n = {sizes})",
                    )
                    ax.fill_between(xs, d[low], d[high], color=color, alpha=0.15, lw=0)
                    if not x:
                        ax.vlines(xs, d[low], d[high], color=color)
                if kind == "power":
                    ax.axhline(0.8, color="#999999", lw=0.6, ls=":")
                    ax.set_ylim(0, 1.02)
                else:
                    ax.axhline(0.0, color="#999999", lw=0.6)
                ax.set_title(_measure_label(measure) + (f"\n{label}" if label else ""))
                if c == 0:
                    ax.set_ylabel(
                        "power (p < .05)" if kind == "power" else "effect, Hedges' g_av (HV - VO)"
                    )
                if r == len(rows) - 1:
                    if x:
                        ax.set_xlabel(FACTOR_LABELS[x])
                    else:
                        ax.set_xticks(range(len(groups)), groups)
        axes[0][-1].legend(frameon=False, loc="best")
        fig.suptitle(f'{plotted(summary, factors, x, kind)}\n"{title}" ({SIMULATED_NOTE})')
    return fig


def draw_figures(summary: pd.DataFrame, factors: list[str], title: str, out: Path) -> list[Path]:
    """Every figure of a campaign as PDF and PNG in `out`; the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    swept: list[str | None] = [f for f in factors if summary[f].nunique() > 1]
    swept = swept or [None]  # nothing swept: one figure over the groups
    paths: list[Path] = []
    for x in swept:
        for kind in ("power", "effect"):
            fig = plot_factor(summary, factors, x, kind, title)
            paths += save(fig, out, f"{kind}_{x or 'groups'}", ("pdf", "png"))
            plt.close(fig)
    return paths
