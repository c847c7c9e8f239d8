"""The compensation law of `compensation.py` as a numba function with no package imports,
so the simulated device's kernel (`simulate.py`) can call it without an import cycle."""

import numpy as np

from teleop_core._jit import njit

# the kernel's compensation vector (`KarnoppCompensator.as_array`): on flag, Coulomb
# level and the gains by direction
COMP_ON, COMP_COULOMB, COMP_GAIN_POS, COMP_GAIN_NEG = range(4)
COMPENSATION_SIZE = 4


@njit(cache=True)
def compensated_command(
    f: float,
    df: float,
    v_m: float,
    stick_velocity: float,
    coulomb: float,
    gain_pos: float,
    gain_neg: float,
) -> float:
    """Motor command that renders `f` through friction `coulomb` and the direction gains.

    `df` is the change of `f` since the last command, `v_m` the manipulator's velocity.
    """
    # Karnopp: direction of motion, or of the force change while stuck
    if abs(v_m) >= stick_velocity:
        d = np.sign(v_m)
    else:
        d = np.sign(df)
    # u = (f + F_c d) / g(direction of u)
    target = f + coulomb * d
    return target / (gain_pos if target >= 0.0 else gain_neg)
