"""Recordings for the generalisation bench: any family, random parameters, any strength.

A clean simulated follower recording (`synthetic.follower_recording`: eq. 1 exactly,
with its sensor noise) gets one, two or three effects added to its reference force,
each with its parameters drawn uniformly (log-uniformly where marked) over the ranges
of `RANGES` and its RMS force drawn log-uniformly from `STRENGTH_JND` times the JND
(0.192 N). Every effect acts on the true (noise-free) current, motion and force, and
the sensors' noise of the clean recording is added afterwards. The additive effects
are summed; slip then saturates the delivered force at the level that takes the drawn
RMS away from it; a lag or a delay then acts on the whole force (as a sensor or a
force-loop lag does), and its size is what the drawn lag makes of it.

The oracle knows the truth: eq. 1's columns plus one column, the exact deviation of
the recorded force from eq. 1's force (y with the effects minus y without), fitted on
the training block. Its held-out RMSE is the floor a model that knew the effect's
shape would reach.

`NAMES` says which report names count as the right family for each injected one
(the loop's family, or the open library's term; none for slip, which the library has
no term for, so that any name given is a wrong one: the loop reports the current
nonlinearity it looks like as ambiguous with `force_saturation`).

Simulated data, not measured: every result built from these says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal

from teleop_core._typing import Float1D
from teleop_core.calibration.effects import play_operator, smooth_sign
from teleop_core.calibration.models import CalibrationData, FollowerBase
from teleop_core.calibration.synthetic import JND_N, follower_recording
from teleop_core.calibration.verdict import distance_since_reversal

STRENGTH_JND = (0.5, 3.0)
"""RMS force of each effect, in JNDs (log-uniform)."""

RANGES: dict[str, dict[str, tuple[float, float, str]]] = {
    "stribeck": {"stribeck_speed_rad_s": (0.05, 2.0, "log")},
    "viscous_nonlinear": {"exponent": (1.5, 3.0, "lin")},
    "direction_asymmetry": {"viscous_share": (0.0, 1.0, "lin")},
    "position_periodic": {"cycles_per_rad": (0.5, 40.0, "log")},
    "hysteresis": {"loop_half_width_a": (0.02, 0.12, "log")},
    "delay": {"lag_s": (0.005, 0.08, "log")},
    "drift": {"time_constant_ratio": (0.3, 3.0, "log")},
    "current_nonlinearity": {"power": (2.0, 3.0, "lin")},
    "presliding_memory": {"memory_rad": (0.01, 1.0, "log")},
    "load_friction": {"load_exponent": (0.7, 1.4, "lin")},
    "gain_change": {"change_fraction": (0.15, 0.85, "lin")},
    "ripple_harmonics": {
        "cycles_per_rad_1": (0.5, 10.0, "log"),
        "cycles_per_rad_2": (2.0, 40.0, "log"),
    },
    "lag": {"time_constant_s": (0.005, 0.06, "log")},
    "backlash": {"half_gap_rad": (0.005, 0.1, "log")},
    "slip": {},
    "direction_gain": {},
    "gap_loss": {"half_gap_rad": (0.005, 0.5, "log")},
}
"""Per family, each drawn parameter: (low, high, "log" | "lin")."""
EXTRA = ("direction_gain", "gap_loss")
"""Families drawn only when asked for by name (`--family`), outside the default plan
(whose recordings keep their seeds): a torque per amp that differs by direction of
motion, and a gap in the drive that passes none of the current's force at a turn and
all of it once crossed, over a range of gaps five times the `backlash` group's."""
FAMILIES = tuple(f for f in RANGES if f not in EXTRA)
"""Every family of the default bench: the loop's eight and the open ones."""
NAMED = FAMILIES[:8]
OPEN = FAMILIES[8:]
WRAPPING = ("delay", "lag")
"""Families that act on the whole force rather than add to it."""
NAMES: dict[str, frozenset[str]] = {
    **{f: frozenset({f}) for f in NAMED},
    "presliding_memory": frozenset({"presliding_memory"}),
    "load_friction": frozenset({"load_friction"}),
    "gain_change": frozenset({"gain_change"}),
    "ripple_harmonics": frozenset({"position_periodic"}),
    "lag": frozenset({"first_order_lag"}),
    "backlash": frozenset({"backlash"}),
    "slip": frozenset(),
    "direction_gain": frozenset({"direction_asymmetry"}),
    "gap_loss": frozenset({"backlash"}),
}
"""Report names that count as the right family for an injected one."""


@dataclass(frozen=True)
class Drawn:
    data: CalibrationData
    deviation: Float1D
    """The recorded force minus eq. 1's force (the oracle's extra column), N."""
    truth: list[dict[str, Any]]


def _draw(family: str, rng: np.random.Generator) -> dict[str, float]:
    out = {}
    for name, (lo, hi, scale) in RANGES[family].items():
        if scale == "log":
            out[name] = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        else:
            out[name] = float(rng.uniform(lo, hi))
    return out


def _shape(family: str, p: dict[str, float], s: dict[str, Float1D], rng) -> Float1D:
    """Unit shape of an additive effect."""
    w, theta, t, iq = s["speed"], s["angle"], s["t"], s["drive"]
    sign = smooth_sign(w)
    if family == "stribeck":
        return -np.exp(-((w / p["stribeck_speed_rad_s"]) ** 2)) * sign
    if family == "viscous_nonlinear":
        return -np.sign(w) * np.abs(w) ** p["exponent"]
    if family == "direction_asymmetry":
        c = -np.minimum(sign, 0.0)
        v = -np.minimum(w, 0.0)
        a = p["viscous_share"]
        return (1 - a) * c / _rms(c) + a * v / _rms(v)
    if family == "position_periodic":
        return np.sin(2 * np.pi * theta * p["cycles_per_rad"] + rng.uniform(0, 2 * np.pi))
    if family == "hysteresis":
        return play_operator(np.ascontiguousarray(iq), p["loop_half_width_a"])
    if family == "drift":
        tau = p["time_constant_ratio"] * (t[-1] - t[0])
        return -iq * (1.0 - np.exp(-(t - t[0]) / tau))
    if family == "current_nonlinearity":
        return -np.sign(iq) * np.abs(iq) ** p["power"]
    if family == "presliding_memory":
        d = distance_since_reversal(theta, w)
        return -sign * np.exp(-d / p["memory_rad"])
    if family == "load_friction":
        return -sign * np.abs(iq) ** p["load_exponent"]
    if family == "gain_change":
        tc = t[0] + p["change_fraction"] * (t[-1] - t[0])
        return iq * (t >= tc)
    if family == "ripple_harmonics":
        ph = rng.uniform(0, 2 * np.pi, 2)
        return np.sin(2 * np.pi * theta * p["cycles_per_rad_1"] + ph[0]) + 0.7 * np.sin(
            2 * np.pi * theta * p["cycles_per_rad_2"] + ph[1]
        )
    if family == "direction_gain":
        # the current's force while the wheel turns backwards
        return iq * (w < 0)
    if family == "gap_loss":
        h = play_operator(np.ascontiguousarray(theta), p["half_gap_rad"])
        return (np.abs(h) - 1.0) * iq
    if family == "backlash":
        # the force carried through a gap: while the wheel crosses it after a reversal
        # the force held by the load's side changes linearly with the position
        return play_operator(np.ascontiguousarray(theta), p["half_gap_rad"])
    raise ValueError(f"family {family!r}; expected one of {', '.join(FAMILIES)}")


def _rms(x: Float1D) -> float:
    return max(float(np.sqrt(np.mean(x * x))), 1e-12)


def _slip(f: Float1D, rms_n: float) -> Float1D:
    """The delivered force saturated at +-level, the level taking `rms_n` away."""
    a = np.abs(f)
    lo, hi = 0.0, float(a.max())
    for _ in range(50):
        level = 0.5 * (lo + hi)
        if _rms(np.clip(f, -level, level) - f) > rms_n:
            lo = level
        else:
            hi = level
    return np.clip(f, -hi, hi)


def general_recording(
    families: tuple[str, ...], seed: int, duration_s: float = 240.0, rate_hz: float = 200.0
) -> Drawn:
    """A follower recording with `families` drawn from `seed` (none: a clean one)."""
    rng = np.random.default_rng([seed, 4242])
    true: dict[str, Float1D] = {}
    rec, _ = follower_recording(duration_s, (), rate_hz=rate_hz, seed=seed, noise_free=true)
    data = FollowerBase().data(rec)
    # the effects act on the true current and motion; the sensors' noise is on top
    s, y0 = true, data.y
    noise = y0 - true["force"]
    y = true["force"].copy()
    truth = []
    additive = [f for f in families if f not in WRAPPING and f != "slip"]
    for family in additive:
        p = _draw(family, rng)
        size = JND_N * float(np.exp(rng.uniform(*np.log(STRENGTH_JND))))
        shape = _shape(family, p, s, rng)
        y = y + size * shape / _rms(shape)
        truth.append({"family": family, "params": p, "rms_n": size, "strength_jnd": size / JND_N})
    if "slip" in families:
        size = JND_N * float(np.exp(rng.uniform(*np.log(STRENGTH_JND))))
        y = _slip(y, size)
        truth.append({"family": "slip", "params": {}, "rms_n": size, "strength_jnd": size / JND_N})
    dt = float(np.median(np.diff(s["t"])))
    for family in (f for f in families if f in WRAPPING):
        p = _draw(family, rng)
        before = y
        if family == "delay":
            y = np.interp(s["t"] - p["lag_s"], s["t"], y)
        else:
            a = np.exp(-dt / p["time_constant_s"])
            y = signal.lfilter([1 - a], [1, -a], y, zi=[a * y[0]])[0]
        size = _rms(y - before)
        truth.append({"family": family, "params": p, "rms_n": size, "strength_jnd": size / JND_N})
    y = y + noise
    name = "+".join(families) or "clean"
    data = CalibrationData(data.signals, y, f"{name} (seed {seed}, simulated)")
    return Drawn(data, y - y0, truth)


def shown_in_training(truth: list[dict[str, Any]], held_out_fraction: float = 0.25) -> bool:
    """Whether the training block (all but the last `held_out_fraction`) shows every
    drawn effect: not so for a gain change drawn after the training block's end, which
    no fit on that block can see (the oracle, knowing the deviation, still gets it
    right on the held-out block). Every other family acts throughout the recording."""
    return all(
        t["family"] != "gain_change" or t["params"]["change_fraction"] < 1.0 - held_out_fraction
        for t in truth
    )


def oracle_rmse(drawn: Drawn, held_out_fraction: float = 0.25) -> float:
    """Held-out RMSE of eq. 1 plus the true deviation's column, fitted on training."""
    data = drawn.data
    X = np.column_stack([FollowerBase().columns(data.signals), drawn.deviation])
    cut = round(len(data) * (1 - held_out_fraction))
    coef, *_ = np.linalg.lstsq(X[:cut], data.y[:cut], rcond=None)
    e = data.y[cut:] - X[cut:] @ coef
    return float(np.sqrt(np.mean(e * e)))
