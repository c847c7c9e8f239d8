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
| `backlash`          | play operator h of the angle (+-1     | half gap | a gap in the drive      |
|                     | after 2 half gaps of travel), and     |          |                         |
|                     | (abs(h) - 1) drive                    |          |                         |

None maps to a named family. `presliding_memory` and `backlash` both change the
friction over the travel after a reversal (an exponential approach against a linear
one across the gap): on a recording whose reversals do not tell the two shapes apart
they tie, and the loop reports the winner as ambiguous with the other (`loop.py`).

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
from teleop_core.calibration.effects import Effect, Signals, noise_sd, play_operator, smooth_sign


def _sign(s: Signals) -> Float1D:
    return s["direction_sign"] if "direction_sign" in s else smooth_sign(s["speed"])


class OpenTerm(Effect):
    """A library term; `formula` is what the report prints, `maps_to` its family."""

    formula: ClassVar[str] = ""
    maps_to: ClassVar[str] = "no named family"
    look_alike: ClassVar[bool | frozenset[str]] = True
    """Whether a tie with a named winner makes the winner ambiguous (`loop.py`): always,
    never, or only for winners of these families."""


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
    # effect that acts there: such a tie says nothing about the winner. A drift is
    # another matter: a gain that settles within a fraction of the recording and a
    # gain that steps there change the force alike
    look_alike = frozenset({"drift"})

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
        # down to a ten-thousandth of the typical stroke: a bristle memory is a small
        # fraction of a degree at the motor, a stroke tens of radians
        d = _distance_since_turn(s["angle"])
        top = float(np.percentile(d, 90)) or 1.0
        return np.geomspace(top / 1e4, top, 28)

    def columns(self, s: Signals, value: float) -> Float2D:
        d = _distance_since_turn(s["angle"])
        return (-_sign(s) * np.exp(-d / value))[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"extra_friction_after_reversal_{unit}": coef[0] * out, "memory_length": value}


class Backlash(OpenTerm):
    """A gap in the drive: after each reversal the force the load side holds changes
    linearly with the travel until the gap is crossed, then stays (the play operator h
    of the angle, the same operator as `hysteresis` has on the drive), and the drive's
    force passes on only as the gap closes (the current's force times |h| - 1: all of
    it lost at the turn, none once the gap is crossed)."""

    family = "backlash"
    needs = ("angle", "drive")
    searched = "half_gap"
    formula = "play_operator(angle, half_gap)"

    def grid(self, s: Signals) -> Float1D:
        # from a ten-thousandth of the typical stroke (and two encoder counts) to half
        # of it: a drive's gap is a fraction of a degree, a stroke tens of radians
        x = s["angle"]
        top = float(np.percentile(distance_since_turn(x), 90)) or 1.0
        steps = np.abs(np.diff(x))
        moving = steps[steps > 1e-9 * max(1.0, float(np.max(np.abs(x))))]
        count = float(moving.min()) if len(moving) else 0.0
        return np.geomspace(min(max(2.0 * count, 1e-4 * top), top / 4.0), top / 2.0, 30)

    def columns(self, s: Signals, value: float) -> Float2D:
        h = play_operator(np.ascontiguousarray(s["angle"]), value)
        # the force held across the gap, and the drive's force that the open gap does
        # not pass on (all of it at the turn, none once the gap is crossed)
        return np.column_stack([h, (np.abs(h) - 1.0) * s["drive"]])

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {
            f"force_across_gap_{unit}": coef[0] * out,
            f"drive_force_lost_in_gap_{unit}_per_drive_unit": coef[1] * out,
            "half_gap": value,
        }


_LAST_TURNS: list[tuple[Float1D, Float1D]] = []
"""The last angle array `_distance_since_turn` was given and its result."""


def _distance_since_turn(angle: Float1D) -> Float1D:
    """`distance_since_turn` of the very array it was last given (the same object, so
    unchanged: the loop's arrays are never written to) without computing it again: a
    search calls it for every value tried, on the same angle."""
    if _LAST_TURNS and _LAST_TURNS[0][0] is angle:
        return _LAST_TURNS[0][1]
    d = distance_since_turn(angle)
    _LAST_TURNS[:] = [(angle, d)]
    return d


def distance_since_turn(angle: Float1D) -> Float1D:
    """|angle - angle at its last turning point| (from the start until the first).

    Turning points from the angle itself, not from the sign of the speed: a speed
    sensor's noise changes the sign at every slow stretch, and each false reversal
    would restart the memory. A turn counts once the angle has come back by twice a
    deadband (a play operator's half width: three noise SDs of the angle's steps, and
    at least one and a half of its smallest step, an encoder's count, and never within
    rounding of zero); the turning point is then the last sample at the extreme of the
    angle since the turn before.
    """
    x = np.ascontiguousarray(angle, dtype=float)
    # steps below a billionth of the angle's size are rounding, not motion
    rounding = 1e-9 * max(1.0, float(np.max(np.abs(x))))
    steps = np.abs(np.diff(x))
    smallest = float(steps[steps > rounding].min()) if np.any(steps > rounding) else 0.0
    half_width = max(3.0 * noise_sd(np.diff(x)), 1.5 * smallest, rounding)
    # the direction once the angle has crossed most of the band (|h| > 0.5: h sits at
    # +-1 only up to rounding, since the band is narrow against the angle)
    h = play_operator(x, half_width)
    full = np.flatnonzero(np.abs(h) > 0.5)
    if len(full) == 0:
        return np.abs(x - x[0])
    held = np.sign(h[np.maximum.accumulate(np.where(np.abs(h) > 0.5, np.arange(len(x)), 0))])
    held[: full[0]] = held[full[0]]
    turn = np.zeros(len(x), dtype=np.int64)
    previous = 0
    for c in np.flatnonzero(np.diff(held) != 0) + 1:
        stroke = x[previous:c] if held[c] < 0 else -x[previous:c]
        # the last sample at the extreme: a stroke that ends in a rest turns where the
        # motion leaves it, and the memory holds while the axis stands
        k = previous + int(np.flatnonzero(stroke >= stroke.max() - rounding)[-1])
        # the extreme itself is the old stroke's end; the new one starts after it
        turn[min(k + 1, len(x) - 1)] = previous = k
    return np.abs(x - x[np.maximum.accumulate(turn)])


OPEN_TERMS: dict[str, OpenTerm] = {
    e.family: e for e in (LoadFriction(), GainChange(), PreslidingMemory(), Backlash())
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
