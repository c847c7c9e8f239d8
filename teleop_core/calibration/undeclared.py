"""Follower recordings carrying one effect that is *not* one of the named families,
with the oracle: the base model plus the true effect's shape.

A clean `synthetic.follower_recording` (eq. 1 exactly, with its sensor noise) gets one
of these forces added to its reference force, scaled to the JND's RMS (0.192 N) over
the recording, its parameters drawn from the seed:

- `load_friction`: friction that grows with the load, -sgn(w) |i_q| (Coulomb friction
  proportional to the normal force a loaded wheel presses with);
- `gain_change`: the torque constant stepping at a drawn time in the first 70 % of the
  recording (a connector, a temperature switch), i_q [t >= t_c];
- `ripple_harmonics`: two ripple harmonics of the wheel angle at drawn periods;
- `presliding_memory`: friction that builds up over a drawn distance after each
  reversal (pre-sliding, Dahl-like), -sgn(w) exp(-d / delta);
- `hidden_force`: a slow random force that never reaches the current, speed or angle:
  no channel can explain it, so the honest verdict is `structure_remains`.

The oracle's held-out RMSE is the noise floor a model that knows the effect reaches.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from teleop_core._typing import Float1D, Float2D
from teleop_core.calibration.effects import SIGN_SPEED_RAD_S
from teleop_core.calibration.models import CalibrationData, FollowerBase
from teleop_core.calibration.synthetic import JND_N, follower_recording
from teleop_core.calibration.verdict import distance_since_reversal

UNDECLARED = (
    "load_friction",
    "gain_change",
    "ripple_harmonics",
    "presliding_memory",
    "hidden_force",
)
VISIBLE = UNDECLARED[:-1]
"""Those a model of the recorded channels can explain."""


def _shape(kind: str, s: dict[str, Float1D], rng: np.random.Generator) -> tuple[Float2D, dict]:
    w, t, theta = s["speed"], s["t"], s["angle"]
    sign = np.tanh(w / SIGN_SPEED_RAD_S)
    if kind == "load_friction":
        return (-sign * np.abs(s["drive"]))[:, None], {}
    if kind == "gain_change":
        tc = float(t[0] + rng.uniform(0.3, 0.7) * (t[-1] - t[0]))
        return (s["drive"] * (t >= tc))[:, None], {"change_time_s": tc}
    if kind == "ripple_harmonics":
        p1, p2 = rng.uniform(0.3, 1.2), rng.uniform(0.05, 0.25)
        phase = rng.uniform(0, 2 * np.pi, 2)
        col = np.sin(2 * np.pi * theta / p1 + phase[0]) + 0.8 * np.sin(
            2 * np.pi * theta / p2 + phase[1]
        )
        return col[:, None], {"period_1_rad": p1, "period_2_rad": p2}
    if kind == "presliding_memory":
        delta = rng.uniform(0.2, 1.0)
        # turns of the true motion: the bristles do not follow the speed sensor's noise
        d = distance_since_reversal(s["true_angle"], s["true_speed"])
        return (-sign * np.exp(-d / delta))[:, None], {"memory_rad": delta}
    if kind == "hidden_force":
        n = len(t)
        kernel = np.ones(max(int(2.0 / float(np.median(np.diff(t)))), 1))
        col = np.convolve(rng.normal(0, 1, n), kernel / len(kernel), mode="same")
        return col[:, None], {}
    raise ValueError(f"undeclared effect {kind!r}; expected one of {', '.join(UNDECLARED)}")


def undeclared_recording(
    kind: str,
    duration_s: float = 240.0,
    rate_hz: float = 200.0,
    seed: int = 0,
    size_n: float = JND_N,
) -> tuple[CalibrationData, Float2D, dict[str, Any]]:
    """Calibration data with `kind` added, the oracle's extra columns, and the truth."""
    true: dict[str, Float1D] = {}
    rec, _ = follower_recording(duration_s, (), rate_hz=rate_hz, seed=seed, noise_free=true)
    data = FollowerBase().data(rec)
    rng = np.random.default_rng(seed + 1000)
    s = {**data.signals, "true_angle": true["angle"], "true_speed": true["speed"]}
    shape, truth = _shape(kind, s, rng)
    scale = size_n / float(np.sqrt(np.mean(shape.sum(axis=1) ** 2)))
    y = data.y + scale * shape.sum(axis=1)
    truth.update(scale=scale, rms_n=size_n)
    oracle = shape if kind != "ripple_harmonics" else _ripple_oracle(data.signals, truth)
    return CalibrationData(data.signals, y, f"{kind} (seed {seed})"), oracle, truth


def _ripple_oracle(s: dict[str, Float1D], truth: dict) -> Float2D:
    theta = s["angle"]
    cols = []
    for p in (truth["period_1_rad"], truth["period_2_rad"]):
        cols += [np.sin(2 * np.pi * theta / p), np.cos(2 * np.pi * theta / p)]
    return np.column_stack(cols)


def oracle_rmse(data: CalibrationData, oracle: Float2D, held_out_fraction: float = 0.25) -> float:
    """Held-out RMSE of eq. 1 plus the true effect's columns, fitted on training."""
    X = np.column_stack([FollowerBase().columns(data.signals), oracle])
    cut = round(len(data) * (1 - held_out_fraction))
    coef, *_ = np.linalg.lstsq(X[:cut], data.y[:cut], rcond=None)
    e = data.y[cut:] - X[cut:] @ coef
    return float(np.sqrt(np.mean(e * e)))
