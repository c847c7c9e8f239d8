"""One round's candidates in the calibration loop (`loop.py`): what the loop records of
each (`Candidate`), which families a round tries, which passing one wins, why one fails,
and whether a searched value sits at the end of its range."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from teleop_core._typing import Float1D
from teleop_core.calibration.effects import EFFECTS, Effect
from teleop_core.calibration.fitting import Chain
from teleop_core.calibration.library import OPEN_TERMS, OpenTerm


@dataclass
class Candidate:
    """One candidate's evaluation in one round."""

    family: str
    """The effect family's report name."""
    round: int
    """Loop round, from 1."""
    searched_value: float
    """Its searched parameter as found on the training block (nan when it has none)."""
    rmse_held_out_n: float
    """Held-out RMSE of the model with it, N (N m for a torque model)."""
    gain_fraction: float
    """Relative cut in held-out RMSE against the model of that round."""
    p_value: float
    """One-sided Diebold-Mariano p-value of that cut."""
    bic_change: float
    """Change of the training BIC when it is added (negative: better)."""
    accepted: bool = False
    """Whether the loop added it in this round."""
    reason: str = ""
    """Why it was not added ('' when it passed)."""


@dataclass(frozen=True)
class ChainFit:
    """A chain of effects on the base model, fitted on the training block."""

    coef: Float1D
    """The design's coefficients."""
    pred: Float1D
    """The prediction over every sample (N, or N m for a torque model)."""
    n_params: int
    """Coefficients and searched values: what the BIC counts."""


@dataclass(frozen=True)
class Found:
    """A candidate of a round: its evaluation, its effect and the fit of the chain with
    it."""

    candidate: Candidate
    effect: Effect
    fit: ChainFit


OPEN = "(open library)"
"""Marks where in a round the open library's terms join the candidates."""
REPEATABLE = {"position_periodic": 3}
"""Families that may enter more than once (several ripple periods), and how often."""


def _best(passing: list[Found], min_gain: float) -> Found:
    """The passing candidate with the lowest held-out error; a named family keeps its
    place unless an open library term cuts the error by `min_gain` more than it."""
    best = min(passing, key=lambda f: f.candidate.rmse_held_out_n)
    named = [f for f in passing if not isinstance(f.effect, OpenTerm)]
    if named and isinstance(best.effect, OpenTerm):
        top = min(named, key=lambda f: f.candidate.rmse_held_out_n)
        if best.candidate.rmse_held_out_n > (1.0 - min_gain) * top.candidate.rmse_held_out_n:
            return top
    return best


def _remaining(families: Sequence[str], chain: Chain, marker: bool = True) -> list[str]:
    """Candidates of a round: families not yet in the chain (a repeatable one until its
    count), then the marker after which the open library may join."""
    used = [e.family for e, _ in chain]
    out = [f for f in families if used.count(f) < REPEATABLE.get(f, 1)]
    return [*out, OPEN] if marker else out


UNLOCATED_AT = {"delay": "upper", "drift": "lower"}
"""Families whose searched value at that end of its range means the effect was not
found. `delay`'s range ends at an arbitrary 0.1 s, and a lag pinned there stands in
for a slower dynamic (on the simulated NOTES rotation ramp it took the friction's
place before the direction asymmetry could). `drift`'s time constant at its lower end
(2 % of the recording) is no slow change but a step in the gain at the start (seen on
NOTES chirps). The other ends are physical: a hysteresis loop of the smallest width
the noise allows is a sharp relay loop, a drift slower than the recording is linear;
those are reported as warnings, not refused."""


def _search_edge(
    effect: Effect, value: float, signals: dict[str, Float1D]
) -> tuple[str, str] | None:
    """("lower" | "upper", message) when `value` sits at an end of `effect`'s search
    range, else None."""
    if effect.searched is None or effect.family == "position_periodic":
        return None
    grid = effect.grid(signals)
    lo, hi = float(np.min(grid)), float(np.max(grid))
    side = "lower" if value <= lo * 1.001 else "upper" if value >= hi * 0.999 else None
    if side is None:
        return None
    where = f"search range [{lo:.4g}, {hi:.4g}]"
    return side, f"{effect.searched} = {value:.4g} is at the end of its {where}"


def _verdict(c: Candidate, min_gain: float, level: float) -> str:
    """Why a candidate fails the significance rule ('' when it passes)."""
    if not c.gain_fraction >= min_gain:
        return f"held-out RMSE cut {100 * c.gain_fraction:.2f} % < {100 * min_gain:.0f} %"
    if not c.p_value < level:
        return f"Diebold-Mariano p = {c.p_value:.3g} >= {level:.3g}"
    if not c.bic_change < 0:
        return f"training BIC rises by {c.bic_change:.1f}"
    return ""


def _candidate_dict(c: Candidate) -> dict[str, Any]:
    d = asdict(c)
    d["searched_value"] = None if np.isnan(c.searched_value) else c.searched_value
    d["searched"] = {**EFFECTS, **OPEN_TERMS}[c.family].searched
    return d
