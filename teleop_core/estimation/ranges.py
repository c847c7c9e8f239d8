"""What the estimator was trained on: the range of each input, and which samples leave it.

A network extrapolates without warning; `study estimator run` flags the samples whose
inputs [I_q, theta_d, theta_dd] lie outside the smallest and largest value each took
in the training samples (column `in_range` of PRED.csv, a summary line with
the share outside). The range is stored in `standardisation.json` as `input_range`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from teleop_core._typing import Float2D
from teleop_core.errors import TeleopInputError

FEATURES = ("iq", "omega", "alpha")
"""The GRU's inputs, in column order: A, rad/s, rad/s^2."""


@dataclass(frozen=True)
class InputRange:
    """Smallest and largest value of each input over the training samples (SI)."""

    low: tuple[float, ...]
    high: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.low) != len(FEATURES) or len(self.high) != len(FEATURES):
            raise TeleopInputError(
                f"input range of {len(self.low)} / {len(self.high)} values; "
                f"expected {len(FEATURES)} ({', '.join(FEATURES)})"
            )
        if any(lo > hi for lo, hi in zip(self.low, self.high, strict=True)):
            raise TeleopInputError(f"input range low {self.low} above high {self.high}")

    @classmethod
    def fit(cls, features: Float2D) -> InputRange:
        """From per-sample inputs, shape (n, 3)."""
        return cls(tuple(features.min(axis=0).tolist()), tuple(features.max(axis=0).tolist()))

    def contains(self, features: Float2D) -> np.ndarray:
        """True for each row of `features` (n, 3) whose every input is inside the range."""
        x = np.asarray(features, float)
        return np.all((x >= np.asarray(self.low)) & (x <= np.asarray(self.high)), axis=1)

    def outside_by_feature(self, features: Float2D) -> dict[str, float]:
        """Share of the rows outside the range, per input."""
        x = np.asarray(features, float)
        out = (x < np.asarray(self.low)) | (x > np.asarray(self.high))
        return {name: float(out[:, k].mean()) for k, name in enumerate(FEATURES)}

    def to_dict(self) -> dict[str, Any]:
        return {"features": list(FEATURES), "low": list(self.low), "high": list(self.high)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> InputRange:
        if list(d.get("features", FEATURES)) != list(FEATURES):
            raise TeleopInputError(
                f"input range over {d.get('features')}; expected {list(FEATURES)}"
            )
        return cls(tuple(float(v) for v in d["low"]), tuple(float(v) for v in d["high"]))
