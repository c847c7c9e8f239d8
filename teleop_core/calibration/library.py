"""The open term library: effects outside the named families.

When no named family passes a round of the loop, these terms compete under the same
held-out rules (gain, Diebold-Mariano, BIC; `loop.py`). Each is a function of the
recorded channels and their history with at most one searched parameter:

| term                | column (coefficient in N)             | searched | what it stands for      |
|---------------------|---------------------------------------|----------|-------------------------|
| `load_friction`     | -sgn(w) abs(drive)                    | -        | load-dependent friction |
| `gain_change`       | drive * [t >= t_c]                    | t_c (s)  | a gain change point     |
| `presliding_memory` | -sgn(w) exp(-d / delta), d = distance | delta    | pre-sliding friction    |
|                     | since reversal                        |          |                         |

None maps to a named family.

Lags of the inputs are the `delay` family's, and powers of speed `viscous_nonlinear`'s.
A second ripple harmonic needs no term here: `position_periodic` may be added more
than once (each time at the largest remaining peak of the residual's periodogram).

Why not SysIdentPy's FROLS or PySINDy: both select among polynomial (NARX) or
user-given candidate functions by orthogonal least squares or sparse regression on
one data set. The terms here carry searched nonlinear parameters (a change time, a
memory length) and must pass the loop's held-out rules, which neither library
applies; the loop's own search-then-test is that sparse forward selection, one term
per round, with held-out error in place of the error-reduction ratio.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from teleop_core._typing import Float1D, Float2D
from teleop_core.calibration.effects import Effect, Signals, smooth_sign
from teleop_core.calibration.verdict import distance_since_reversal


def _sign(s: Signals) -> Float1D:
    return s["direction_sign"] if "direction_sign" in s else smooth_sign(s["speed"])


class OpenTerm(Effect):
    """A library term; `formula` is what the report prints, `maps_to` its family."""

    formula: ClassVar[str] = ""
    maps_to: ClassVar[str] = "no named family"
    look_alike: ClassVar[bool] = True
    """Whether a tie with a named winner makes the winner ambiguous (`loop.py`)."""


class LoadFriction(OpenTerm):
    family = "load_friction"
    needs = ("drive", "speed")
    formula = "-sgn(speed) |drive|"

    def columns(self, s: Signals, value: float) -> Float2D:
        return (-_sign(s) * np.abs(s["drive"]))[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"friction_{unit}_per_drive_unit": coef[0] * out}


class GainChange(OpenTerm):
    family = "gain_change"
    needs = ("drive",)
    searched = "change_time_s"
    log_search = False
    formula = "drive [t >= change_time_s]"
    # a step placed at the held-out block's one reversal or load change ties with any
    # effect that acts there: such a tie says nothing about the winner
    look_alike = False

    def grid(self, s: Signals) -> Float1D:
        t = s["t"]
        return np.linspace(t[0], t[-1], 42)[1:-1]

    def columns(self, s: Signals, value: float) -> Float2D:
        return (s["drive"] * (s["t"] >= value))[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"gain_step_{unit}_per_drive_unit": coef[0] * out, "change_time_s": value}


class PreslidingMemory(OpenTerm):
    family = "presliding_memory"
    needs = ("speed", "angle")
    searched = "memory_length"
    formula = "-sgn(speed) exp(-distance_since_reversal / memory_length)"

    def grid(self, s: Signals) -> Float1D:
        d = distance_since_reversal(s["angle"], s["speed"])
        top = float(np.percentile(d, 90)) or 1.0
        return np.geomspace(top / 300.0, top, 20)

    def columns(self, s: Signals, value: float) -> Float2D:
        d = distance_since_reversal(s["angle"], s["speed"])
        return (-_sign(s) * np.exp(-d / value))[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"extra_friction_after_reversal_{unit}": coef[0] * out, "memory_length": value}


OPEN_TERMS: dict[str, OpenTerm] = {
    e.family: e for e in (LoadFriction(), GainChange(), PreslidingMemory())
}
"""The open library by name."""


def term_report(effect: Effect, params: dict[str, float], ci: dict, share: float) -> dict:
    """A discovered term as the report lists it."""
    return {
        "term": effect.family,
        "formula": getattr(effect, "formula", effect.family),
        "params": params,
        "ci": ci,
        "share_of_explained_variance": share,
        "family": getattr(effect, "maps_to", effect.family),
    }
