"""Figures of the NOTES device's characterisation ([notes], Figs. 6-7 and 9-11).

- `bode`: |F|, |V| and |Z_device| of both axes, measured points with the grey-box fit
  overlaid (Figs. 9-11);
- `ramp_hysteresis`: the clamped static ramp's output against its command, before and
  after the Karnopp/direction compensator (Figs. 6-7, and the compensation the paper
  plans);
- `compensation_table`: the before/after numbers as a tidy frame.

House style of `figures.py` (IEEE widths, Okabe-Ito colours, `save`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from study.analysis.figures import OKABE_ITO, STYLE, WIDTHS_IN
from teleop_core.notes.characterize import AxisCharacterisation
from teleop_core.notes.identify import Frf, GreyBoxFit
from teleop_core.notes.transfer import frequency_response

UNITS: dict[str, dict[str, Any]] = {
    "translation": {"F": "N/N", "V": "m/s per N", "Z": "N s/m", "force": "N", "scale": 1.0},
    "rotation": {
        "F": "N m/N m",
        "V": "rad/s per N m",
        "Z": "N m s/rad",
        "force": "N mm",
        "scale": 1e3,
    },
}
MEASURED = OKABE_ITO["grey"]
MODEL = OKABE_ITO["HV"]
BEFORE = OKABE_ITO["VO"]


class FittedAxis(Protocol):
    """What `bode` draws: `AxisCharacterisation` or a recorded `ChirpFit`."""

    @property
    def dof(self) -> str: ...

    @property
    def frfs(self) -> list[Frf]: ...

    @property
    def fit(self) -> GreyBoxFit: ...

    @property
    def bandwidth_hz(self) -> float: ...


def _measured(ch: FittedAxis) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    frf = {f.which: f for f in ch.frfs}
    out = {k: (v.f_hz, v.h) for k, v in frf.items()}
    if "V" in frf and "F" in frf:
        # Z = F / V on V's frequencies (F interpolated there)
        f = frf["V"].f_hz
        h_f = np.interp(f, frf["F"].f_hz, frf["F"].h.real) + 1j * np.interp(
            f, frf["F"].f_hz, frf["F"].h.imag
        )
        out["Z"] = (f, h_f / frf["V"].h)
    return out


def bode(axes: Sequence[FittedAxis]) -> plt.Figure:
    """Magnitude of F, V and Z_device per axis (columns), measured vs fitted."""
    with plt.rc_context(STYLE):
        fig, grid = plt.subplots(
            3, len(axes), figsize=(WIDTHS_IN["double"], 5.0), squeeze=False, sharex=True
        )
        f_model = np.logspace(0, np.log10(30), 200)
        for col, ch in enumerate(axes):
            measured = _measured(ch)
            for row, which in enumerate(("F", "V", "Z")):
                ax = grid[row][col]
                if which in measured:
                    f, h = measured[which]
                    ax.semilogx(
                        f, 20 * np.log10(np.abs(h)), ".", ms=1.5, color=MEASURED, label="measured"
                    )
                h_fit = frequency_response(ch.fit.params_, which, f_model)
                ax.semilogx(f_model, 20 * np.log10(np.abs(h_fit)), color=MODEL, label="fit")
                ax.set_ylabel(f"|{which}| (dB {UNITS[ch.dof][which]})")
                if row == 0:
                    ax.axhline(-3, color=BEFORE, lw=0.5, ls="--")
                    ax.set_title(f"{ch.dof}: bandwidth {ch.bandwidth_hz:.1f} Hz")
                    ax.legend(frameon=False, loc="lower left")
            grid[-1][col].set_xlabel("frequency (Hz)")
        fig.tight_layout()
    return fig


def ramp_hysteresis(axes: list[AxisCharacterisation]) -> plt.Figure:
    """Clamped ramp output against command, before and after compensation."""
    with plt.rc_context(STYLE):
        fig, grid = plt.subplots(1, len(axes), figsize=(WIDTHS_IN["double"], 2.6), squeeze=False)
        for ax, ch in zip(grid[0], axes, strict=True):
            scale, unit = UNITS[ch.dof]["scale"], UNITS[ch.dof]["force"]
            ax.plot(
                ch.ramp.f_des * scale,
                ch.ramp.y * scale,
                color=BEFORE,
                label=f"uncompensated (hysteresis {ch.before.hysteresis * scale:.3g} {unit})",
            )
            if ch.ramp_compensated is not None and ch.after is not None:
                r = ch.ramp_compensated
                ax.plot(
                    r.f_des * scale,
                    r.y * scale,
                    color=MODEL,
                    label=f"compensated (hysteresis {ch.after.hysteresis * scale:.3g} {unit})",
                )
            lims = [ch.ramp.f_des.min() * scale, ch.ramp.f_des.max() * scale]
            ax.plot(lims, lims, color=MEASURED, lw=0.5, ls=":", label="ideal")
            ax.set_xlabel(f"commanded ({unit})")
            ax.set_ylabel(f"load cell ({unit})")
            ax.set_title(
                f"{ch.dof}: asymmetry {ch.before.asymmetry:.1%} -> "
                f"{ch.after.asymmetry if ch.after else float('nan'):.1%}"
            )
            ax.legend(frameon=False, loc="upper left")
        fig.tight_layout()
    return fig


def compensation_table(axes: list[AxisCharacterisation]) -> pd.DataFrame:
    """Columns: dof, measure, before, after (SI units, rotation in N m)."""
    rows = []
    for ch in axes:
        if ch.after is None:
            continue
        before, after = ch.before.to_dict(), ch.after.to_dict()
        for key in (
            "hysteresis",
            "asymmetry",
            "gain_positive",
            "gain_negative",
            "min_output",
            "max_continuous",
        ):
            rows.append({"dof": ch.dof, "measure": key, "before": before[key], "after": after[key]})
    return pd.DataFrame(rows, columns=["dof", "measure", "before", "after"])
