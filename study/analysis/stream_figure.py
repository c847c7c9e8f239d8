"""The trial figure with the lab's other instruments: the task's forces over time, and
under them each recorded stream the design asks for (`[lsl] plot`, by stream name or
type), on the trial's clock. One column per trial (Fig. 9's VO and HV trials); a
numeric stream's channels are drawn with their names and units, a marker stream's
markers as labelled ticks; where a stream was lost, the gap is shaded.
"""

from __future__ import annotations

from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from study.analysis.figures import STYLE, WIDTHS_IN
from study.analysis.task_figures import figure_view
from study.protocol.tasks import get_task

COLORS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9")


@dataclass
class DrawnStream:
    """One recorded stream of one trial, as drawn."""

    name: str
    type: str
    channels: list[dict[str, str]]
    """[{"name", "unit"}] per channel."""
    frame: pd.DataFrame
    """`t_s` and one column per channel."""
    gaps: list[list[float]]
    is_string: bool = False


def trial_streams_figure(
    task: str,
    trials: list[tuple[pd.DataFrame, str, list[DrawnStream]]],
    width: str = "double",
) -> plt.Figure:
    """One column per trial: its traced forces on top, one row per stream below.

    Parameters
    ----------
    trials
        (samples with `t_s` and the task's traced force columns, title, streams) per
        column; every column has the same streams, by name, in the same order.
    """
    the_task = get_task(task)
    trials = [
        (samples, title, [part for s in streams for part in _by_unit(s)])
        for samples, title, streams in trials
    ]
    n_rows = 1 + max(len(s) for _, _, s in trials)
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(
            n_rows,
            len(trials),
            figsize=(WIDTHS_IN[width], 1.3 * n_rows + 0.6),
            sharex="col",
            squeeze=False,
            layout="constrained",
        )
        for col, (samples, title, streams) in enumerate(trials):
            top = axes[0, col]
            for k, (column, label) in enumerate(figure_view(the_task).traced_names().items()):
                if column in samples:
                    top.plot(
                        samples["t_s"],
                        samples[column],
                        lw=0.8,
                        color=COLORS[k % len(COLORS)],
                        label=label,
                    )
            top.set_title(title)
            top.set_ylabel("force (N)")
            if col == 0:
                top.legend(loc="upper left", frameon=False)
            for row, stream in enumerate(streams, start=1):
                _draw_stream(axes[row, col], stream, legend=col == 0)
            axes[-1, col].set_xlabel("time in the trial (s)")
    return fig


def _by_unit(stream: DrawnStream) -> list[DrawnStream]:
    """A numeric stream's channels split by unit (one axis each); a string stream whole."""
    if stream.is_string:
        return [stream]
    units = list(dict.fromkeys(c["unit"] for c in stream.channels))
    return [
        DrawnStream(
            stream.name,
            stream.type,
            [c for c in stream.channels if c["unit"] == u],
            stream.frame,
            stream.gaps,
        )
        for u in units
    ]


def _draw_stream(ax: plt.Axes, stream: DrawnStream, legend: bool) -> None:
    t = stream.frame["t_s"].to_numpy()
    if stream.is_string:
        column = stream.channels[0]["name"]
        for when, text in zip(t, stream.frame[column], strict=True):
            ax.axvline(when, color="black", lw=0.6)
            ax.text(
                when,
                0.9,
                str(text)[:24],
                rotation=90,
                va="top",
                ha="right",
                transform=ax.get_xaxis_transform(),
            )
        ax.set_yticks([])
    else:
        units = {c["unit"] for c in stream.channels}
        for k, ch in enumerate(stream.channels):
            label = f"{ch['name']} ({ch['unit']})" if ch["unit"] else ch["name"]
            ax.plot(
                t,
                stream.frame[ch["name"]].to_numpy(dtype=float),
                lw=0.7,
                color=COLORS[k % len(COLORS)],
                label=label,
            )
        unit = units.pop() if len(units) == 1 else ""
        ax.set_ylabel(f"{stream.type} ({unit})" if unit else stream.type)
        if legend:
            ax.legend(loc="upper right", frameon=False, ncols=min(len(stream.channels), 3))
    for start, end in stream.gaps:
        ax.axvspan(start, end, color="#999999", alpha=0.3, lw=0)
    if stream.gaps:
        ax.text(
            float(np.mean(stream.gaps[0])),
            0.5,
            "lost",
            ha="center",
            transform=ax.get_xaxis_transform(),
        )
    ax.set_title(f"{stream.name}", loc="left", fontsize=STYLE["font.size"])
