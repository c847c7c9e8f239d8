"""What the guidewire meets: environments the loop kernel calls at the device rate.

An environment is a numba function with the signature documented in `kernel.py`, plus
its state and parameter arrays. The LCCA phantom provides one; here are the simple
ones the loop's benches and tests use.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from teleop_core._jit import njit
from teleop_core.errors import TeleopInputError
from teleop_core.loop.layout import E_DISTAL, E_PROXIMAL, E_SUCCESS, E_TIP_X


@dataclass
class Environment:
    """A compiled environment function with its state and parameters."""

    fn: Callable[..., None]
    params: np.ndarray
    state: np.ndarray = field(default_factory=lambda: np.zeros(1))
    name: str = "environment"
    branches: tuple[str, ...] = ("",)
    """Names of the branch codes the function writes (index = code)."""

    def reset(self) -> None:
        self.state[:] = 0.0


@njit(cache=True)
def _free_space(state, params, insertion_m, speed_m_s, rotation_rad, dt_s, out):
    out[:] = 0.0
    out[E_TIP_X] = insertion_m


# `tube_with_wall`'s parameter vector
TW_FRICTION, TW_WALL_DEPTH, TW_WALL_K, TW_V_SCALE, TW_TARGET = range(5)


@njit(cache=True)
def _tube_with_wall(state, params, insertion_m, speed_m_s, rotation_rad, dt_s, out):
    friction_per_m, wall_depth, wall_k = (
        params[TW_FRICTION],
        params[TW_WALL_DEPTH],
        params[TW_WALL_K],
    )
    v_scale, target = params[TW_V_SCALE], params[TW_TARGET]
    # sliding friction along the inserted length, smoothed through zero speed
    inserted = max(insertion_m, 0.0)
    f_friction = friction_per_m * inserted * math.tanh(speed_m_s / v_scale)
    # the tip meets a wall: a stiff spring beyond wall_depth
    f_contact = wall_k * max(insertion_m - wall_depth, 0.0)
    out[:] = 0.0
    out[E_PROXIMAL] = f_friction + f_contact
    out[E_DISTAL] = f_contact
    out[E_TIP_X] = insertion_m
    out[E_SUCCESS] = 1.0 if insertion_m >= target else 0.0


def free_space() -> Environment:
    """No load: the guidewire moves in air."""
    return Environment(_free_space, np.zeros(1), name="free space")


def tube_with_wall(
    friction_n_per_m: float = 4.0,
    wall_depth_m: float = 0.30,
    wall_stiffness_n_per_m: float = 400.0,
    smoothing_speed_m_s: float = 0.002,
    target_depth_m: float = 0.25,
) -> Environment:
    """A straight tube: friction growing with the inserted length, a wall at the end.

    Success when the tip passes `target_depth_m`.
    """
    values = (friction_n_per_m, wall_depth_m, wall_stiffness_n_per_m, smoothing_speed_m_s)
    if not all(math.isfinite(v) and v > 0 for v in (*values, target_depth_m)):
        raise TeleopInputError(f"tube parameters {values}; expected finite values > 0")
    return Environment(
        _tube_with_wall,
        np.array([*values, target_depth_m], dtype=np.float64),
        name="tube with wall",
    )
