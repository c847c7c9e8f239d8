"""Speed commands and load forces that exercise the simulated drive like the paper's benches.

All profiles are sampled at the drive's 1 kHz tick. `teleoperation` imitates the
dataset of [endovascular], IV-C (a guidewire advanced, held and withdrawn through a phantom
by rate control); `sinusoidal_load` the Table II bench (wheel held at zero speed, a
linear stage loading the guidewire through a spring); `ramp` and `step` the Table I
velocity commands. The load model here is a stand-in for the vascular phantom of the
LCCA issue: insertion friction that grows with inserted length and follows the
direction of motion, wall contacts as force bumps while advancing, relaxation at rest.
"""

from __future__ import annotations

import numpy as np

from teleop_core._typing import Float1D
from teleop_core.follower.params import FollowerPlantParams


def _smooth(x: Float1D, tau_s: float, dt_s: float) -> Float1D:
    """First-order low-pass (the dial's rate control does not jump)."""
    a = dt_s / (tau_s + dt_s)
    y = np.empty_like(x)
    acc = x[0]
    for i, v in enumerate(x):
        acc += a * (v - acc)
        y[i] = acc
    return y


def teleoperation(
    duration_s: float,
    rng: np.random.Generator,
    *,
    dt_s: float = 1e-3,
    wheel_radius_m: float = FollowerPlantParams.wheel_radius_m,
    max_speed_rad_s: float = 10.0,
    load_scale: float = 1.0,
    max_load_n: float = 2.5,
    contact_scale: float = 1.0,
) -> tuple[Float1D, Float1D]:
    """A random navigation session: (speed command rad/s, load force N) per tick.

    `load_scale` scales every resistance (a stiffer or narrower vessel), `contact_scale`
    the wall contacts alone (an operator who keeps pushing into the wall).
    """
    n = round(duration_s / dt_s)
    cmd = np.zeros(n)
    i = 0
    while i < n:
        length = int(rng.uniform(0.4, 2.5) / dt_s)
        kind = rng.choice(["advance", "hold", "retract"], p=[0.5, 0.3, 0.2])
        if kind == "advance":
            cmd[i : i + length] = rng.uniform(0.8, max_speed_rad_s)
        elif kind == "retract":
            cmd[i : i + length] = -rng.uniform(0.8, 0.6 * max_speed_rad_s)
        i += length
    cmd = _smooth(cmd, 0.08, dt_s)
    # Inserted length follows the command (the drive tracks it closely); a session
    # navigates at most 0.6 m of vessel.
    inserted = np.clip(np.cumsum(cmd * wheel_radius_m * dt_s), 0.0, 0.6)
    direction = np.tanh(cmd / 0.5)
    friction = direction * (0.12 + 1.6 * inserted)
    bumps = np.zeros(n)
    t = np.arange(n) * dt_s
    for centre in rng.uniform(0, duration_s, size=max(1, int(duration_s / 3))):
        k = min(int(centre / dt_s), n - 1)
        if cmd[k] > 0.5:  # walls are met while advancing
            width = rng.uniform(0.15, 0.8)
            height = contact_scale * rng.uniform(0.3, 1.4)
            bumps += height * np.exp(-0.5 * ((t - centre) / width) ** 2)
    drift = 0.15 * np.sin(2 * np.pi * t / rng.uniform(20, 60) + rng.uniform(0, 2 * np.pi))
    load = _smooth(friction + bumps, 0.05, dt_s) + drift
    # Resistance stays below what the drive can push against (about 3 N at the
    # voltage limit), as a passive vessel cannot drive the wheel backwards.
    return cmd, np.clip(load * load_scale, -1.5, max_load_n)


def sinusoidal_load(
    frequency_hz: float,
    duration_s: float,
    *,
    mean_n: float = 1.0,
    amplitude_n: float = 0.8,
    dt_s: float = 1e-3,
) -> tuple[Float1D, Float1D]:
    """Table II: zero speed command, load mean + amplitude sin(2 pi f t)."""
    t = np.arange(round(duration_s / dt_s)) * dt_s
    ramp_in = np.clip(t / 0.5, 0.0, 1.0)  # the stage takes up the spring gently
    return np.zeros_like(t), ramp_in * (mean_n + amplitude_n * np.sin(2 * np.pi * frequency_hz * t))


def characterisation(
    duration_s: float, rng: np.random.Generator, *, segment_s: float = 10.0, dt_s: float = 1e-3
) -> tuple[Float1D, Float1D]:
    """The calibration platform of [endovascular], IV-C: wheel at zero speed, sinusoidal loads.

    Segments of `segment_s` with a random frequency (0.3-3.5 Hz), mean (0.4-1.2 N) and
    amplitude (0.2-0.8 N), each taken up and released gently.
    """
    cmd_parts, load_parts = [], []
    for _ in range(max(1, round(duration_s / segment_s))):
        _, load = sinusoidal_load(
            rng.uniform(0.3, 3.5),
            segment_s,
            mean_n=rng.uniform(0.4, 1.2),
            amplitude_n=rng.uniform(0.2, 0.8),
            dt_s=dt_s,
        )
        load *= np.clip((segment_s - np.arange(len(load)) * dt_s) / 0.5, 0.0, 1.0)  # release
        cmd_parts.append(np.zeros_like(load))
        load_parts.append(load)
    return np.concatenate(cmd_parts), np.concatenate(load_parts)


def ramp(
    peak_rad_s: float = 10.0, rise_s: float = 2.0, hold_s: float = 1.0, dt_s: float = 1e-3
) -> Float1D:
    """Table I ramp: rest, up to the peak, hold, back down, rest."""
    rest = np.zeros(round(0.5 / dt_s))
    up = np.linspace(0.0, peak_rad_s, round(rise_s / dt_s))
    return np.concatenate([rest, up, np.full(round(hold_s / dt_s), peak_rad_s), up[::-1], rest])


def step(level_rad_s: float = 10.0, hold_s: float = 2.0, dt_s: float = 1e-3) -> Float1D:
    """Table I step: rest, a step to the level, hold, back to rest."""
    rest = np.zeros(round(0.5 / dt_s))
    return np.concatenate(
        [rest, np.full(round(hold_s / dt_s), level_rad_s), np.zeros(round(hold_s / dt_s))]
    )
