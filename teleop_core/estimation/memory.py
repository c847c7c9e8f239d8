"""Memory features for the GRU: each input minus its causal exponential moving average.

The GRU sees the last T samples (0.1 s at 200 Hz at T = 20). An effect whose state
lies further back, such as hysteresis (the direction state turns only after the
current has moved by the loop's width), is not in such a window (physics+GRU barely
beat physics alone on the generalisation bench without them). These features carry the longer past
into every time step at the cost of a few inputs: for I_q and theta_d, the value minus
its exponential moving average at time constants of 0.1, 0.3, 1 and 3 s. They are what
the input did over the last tau seconds, scaled to the GRU's inputs by the same
standardisation as the rest.

The average is causal and one recurrence (`ema_step`) serves the whole recording
(`memory_inputs`, training and `study estimator run`) and the sample-by-sample stream
(`stream.stream_push`, which the loop's compiled kernel calls), so the two agree to the
last bit. With the time step dt_k = t_k - t_{k-1}:

    e_0 = x_0,    e_k = e_{k-1} + (1 - exp(-dt_k / tau)) (x_k - e_{k-1})

so for a unit step at sample s after a constant 0, x_k - e_k = exp(-(k - s + 1) dt / tau).

This module owns the feature definition and its metadata (`MemorySpec`, saved in the
model folder's `standardisation.json` as `memory`); a folder without it (saved before
this module) is the plain window, `MemorySpec.none()`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from teleop_core._jit import njit
from teleop_core._typing import Float1D, Float2D
from teleop_core.errors import TeleopInputError

BASE_FEATURES = ("iq", "omega", "alpha")
"""The per-sample inputs, in column order (A, rad/s, rad/s^2)."""
DEFAULT_COLUMNS = ("iq", "omega")
"""I_q and theta_d: the inputs whose past carries the effects a window misses."""
DEFAULT_TIME_CONSTANTS_S = (0.1, 0.3, 1.0, 3.0)
"""Spanning the window (0.1 s) to the slowest hysteresis turn seen on the bench."""


@dataclass(frozen=True)
class MemorySpec:
    """Which inputs get memory features, and at which time constants."""

    time_constants_s: tuple[float, ...] = DEFAULT_TIME_CONSTANTS_S
    """tau of each exponential moving average, s; > 0. Empty: no memory features."""
    columns: tuple[str, ...] = DEFAULT_COLUMNS
    """Inputs (of `BASE_FEATURES`) that get one feature per time constant."""

    def __post_init__(self) -> None:
        for tau in self.time_constants_s:
            if not (isinstance(tau, int | float) and math.isfinite(tau) and tau > 0):
                raise TeleopInputError(f"memory time constant {tau!r} s; expected > 0")
        unknown = [c for c in self.columns if c not in BASE_FEATURES]
        if unknown or len(set(self.columns)) != len(self.columns):
            raise TeleopInputError(
                f"memory columns {list(self.columns)}; expected distinct names of "
                f"{list(BASE_FEATURES)}"
            )

    @classmethod
    def none(cls) -> MemorySpec:
        """No memory features: the plain window of [I_q, theta_d, theta_dd]."""
        return cls((), ())

    @property
    def enabled(self) -> bool:
        return bool(self.time_constants_s) and bool(self.columns)

    @property
    def n_features(self) -> int:
        """Memory features per time step."""
        return len(self.time_constants_s) * len(self.columns) if self.enabled else 0

    @property
    def feature_names(self) -> tuple[str, ...]:
        """All GRU inputs per time step: the base inputs, then `col-ema<tau>s` each."""
        extra = (
            tuple(f"{c}-ema{tau:g}s" for c in self.columns for tau in self.time_constants_s)
            if self.enabled
            else ()
        )
        return BASE_FEATURES + extra

    def kernel_table(self) -> Float2D:
        """Shape (n_features, 2): [column index in BASE_FEATURES, 1 / tau] per feature, in
        `feature_names` order; what `stream.stream_push` reads (0 rows: no memory)."""
        rows = (
            [
                (float(BASE_FEATURES.index(c)), 1.0 / tau)
                for c in self.columns
                for tau in self.time_constants_s
            ]
            if self.enabled
            else []
        )
        return np.ascontiguousarray(np.array(rows, dtype=np.float64).reshape(-1, 2))

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": "ema_residual" if self.enabled else "none",
            "columns": list(self.columns),
            "time_constants_s": list(self.time_constants_s),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> MemorySpec:
        """From `to_dict`'s output; None (a folder saved before memory features) is none."""
        if d is None or d.get("kind") == "none":
            return cls.none()
        if d.get("kind") != "ema_residual":
            raise TeleopInputError(
                f"memory features of kind {d.get('kind')!r}; expected 'ema_residual' or 'none'"
            )
        return cls(
            tuple(float(v) for v in d["time_constants_s"]), tuple(str(c) for c in d["columns"])
        )

    @classmethod
    def parse(cls, text: str) -> MemorySpec:
        """`--memory`: 'none', 'ema' (the defaults) or time constants in s, e.g. '0.1,1'."""
        text = text.strip().lower()
        if text == "none":
            return cls.none()
        if text in ("ema", "default"):
            return cls()
        try:
            taus = tuple(float(v) for v in text.split(","))
        except ValueError:
            raise TeleopInputError(
                f"--memory {text!r}; expected 'none', 'ema' or time constants in s such as "
                "0.1,0.3,1,3"
            ) from None
        return cls(taus)


@njit(cache=True)
def ema_step(e: float, x: float, dt: float, inv_tau: float) -> float:  # pragma: no cover
    # e_k = e_{k-1} + (1 - exp(-dt_k / tau)) (x_k - e_{k-1})
    return e + (1.0 - math.exp(-dt * inv_tau)) * (x - e)


@njit(cache=True)
def _ema_residuals(t, base, table, out):  # pragma: no cover
    for j in range(table.shape[0]):
        col, inv_tau = int(table[j, 0]), table[j, 1]
        e = base[0, col]
        out[0, j] = 0.0
        for k in range(1, base.shape[0]):
            e = ema_step(e, base[k, col], t[k] - t[k - 1], inv_tau)
            out[k, j] = base[k, col] - e


def ema_residuals(t: Float1D, base: Float2D, spec: MemorySpec) -> Float2D:
    """The memory features of a whole recording, shape (n, spec.n_features).

    Parameters
    ----------
    t : (n,) sample times, s, increasing.
    base : (n, 3) per-sample [I_q (A), theta_d (rad/s), theta_dd (rad/s^2)].
    spec : which columns and time constants.

    Returns
    -------
    (n, spec.n_features): x_k - e_k per (column, tau) in `spec.feature_names` order.
    """
    base = np.ascontiguousarray(base, dtype=np.float64)
    out = np.zeros((len(base), spec.n_features))
    if spec.n_features and len(base):
        _ema_residuals(np.ascontiguousarray(t, dtype=np.float64), base, spec.kernel_table(), out)
    return out


def memory_inputs(t: Float1D, base: Float2D, spec: MemorySpec) -> Float2D:
    """The GRU's per-sample inputs: `base` (n, 3) then its memory features, (n, 3 + m)."""
    if not spec.enabled:
        return np.asarray(base, dtype=np.float64)
    return np.hstack([np.asarray(base, dtype=np.float64), ema_residuals(t, base, spec)])
