"""Plausible names only: a family is named only when its fitted
parameters are physically possible; otherwise the candidate is refused under that name
and its evidence stays in the residual (and in the verdict's `unexplained`).

- `stribeck`: the friction must fall with speed, static above Coulomb: the fitted
  static-minus-Coulomb excess must be positive.
- `hysteresis`: the loop must not be negative: its half height must have the sign a
  loss between the drive and the measured force gives in the base model's convention
  (`BaseModel.passive_loop_sign`), which depends on which of the two causes the
  other: + for the follower (the load leads the current the speed loop draws), - for
  a NOTES axis (the force lags the command through the friction). The master is not
  checked: the paper's own branches (eqs. 14-15) cross near 2 mA. A loop of the wrong
  sign is a play operator standing in for something periodic or slow (a second
  ripple harmonic, a force no channel carries), not a hysteresis.
- `drift`: a time constant at either end of its search range locates nothing (a step
  at the start, or a change slower than the recording that a gain change explains).
"""

from __future__ import annotations

import numpy as np

from teleop_core._typing import Float1D
from teleop_core.calibration.effects import Effect, Signals


def implausible(
    effect: Effect,
    coef: Float1D,
    value: float,
    out: float,
    unit: str,
    signals: Signals,
    loop_sign: int | None = None,
) -> str | None:
    """Why `effect` with its coefficients `coef` (its own columns only) cannot be the
    physical family it names, or None when it can. `loop_sign`: the base model's
    `passive_loop_sign` (None: a hysteresis loop's sign is not checked)."""
    params = effect.physical(np.asarray(coef, float), value, out, unit)
    half = params.get(f"half_loop_{unit}")
    # only a constant half height has one sign (the master's quadratic loop has three
    # coefficients and its own sign changes)
    constant = len(coef) == 1
    if effect.family == "hysteresis" and loop_sign and constant and half is not None:
        if half * loop_sign <= 0:
            side = "positive" if loop_sign > 0 else "negative"
            return (
                f"implausible: hysteresis half loop {half:.3g} {unit.replace('_', ' ')} "
                f"is a negative loop (a loss between drive and force gives a {side} "
                "one here)"
            )
    if effect.family == "stribeck":
        excess = next(v for k, v in params.items() if k.startswith("static_minus_coulomb"))
        if excess <= 0:
            return (
                f"implausible: static - Coulomb friction {excess:.3g} <= 0 (a Stribeck "
                "friction falls with speed)"
            )
    if effect.family == "drift" and effect.searched is not None:
        grid = effect.grid(signals)
        lo, hi = float(np.min(grid)), float(np.max(grid))
        if value <= lo * 1.001 or value >= hi * 0.999:
            return (
                f"implausible: drift time constant {value:.3g} s at the end of its "
                f"search range [{lo:.3g}, {hi:.3g}] s"
            )
    return None


def effect_coefficients(coef: Float1D, effect: Effect, signals: Signals, value: float) -> Float1D:
    """The last coefficients of a chain's fit: those of `effect`, appended last."""
    probe = {k: v[:4] for k, v in signals.items()}
    k = effect.columns(effect.transform(probe, value), value).shape[1]
    return np.asarray(coef, float)[len(coef) - k :] if k else np.empty(0)
