"""Friction and direction compensation for the NOTES device ([notes], III-A, IV).

The paper plans "Karnopp's friction model ... to dynamically compensate for the friction"
and "a direction specific compensator" for the flexible shaft's CCW loss. This module
owns both as one feed-forward law inside the impedance controller: the controller
decides the force f to render (the tissue's impedance), and the compensator turns it
into the motor command

    u = (f + F_c_hat * d) / g_hat(d)

with d the direction of the manipulator's motion by Karnopp's rule (sign of its
velocity outside the stick band |v| < dv; inside it, the direction the rendered force
is changing, which is where a clamped or slowly moving manipulator is about to go) and
g_hat the measured transmission of that direction's commands (CW or CCW). The
compensator's numbers are fitted from a clamped static ramp (`KarnoppCompensator.fit`):
the loading branch is g u - F_c and the unloading one g u + F_c, so F_c is half the
gap between them and g the slope of each direction's loading branch.

`compensated_command` (in `karnopp.py`, which imports nothing of the package) is a
numba function so the simulated device's kernel and the
trial's controller use the very same law.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from teleop_core.notes.identify import ramp_measures
from teleop_core.notes.karnopp import (
    COMP_COULOMB,
    COMP_GAIN_NEG,
    COMP_GAIN_POS,
    COMP_ON,
    COMPENSATION_SIZE,
)
from teleop_core.notes.recording import NotesRecording


@dataclass
class KarnoppCompensator:
    """Karnopp friction plus direction-specific gain compensation, fitted from a ramp.

    After `fit`: `coulomb_` (N or N m), `gain_positive_`, `gain_negative_`.
    """

    coulomb_: float = field(default=0.0, init=False)
    gain_positive_: float = field(default=1.0, init=False)
    gain_negative_: float = field(default=1.0, init=False)

    def fit(self, ramp: NotesRecording) -> KarnoppCompensator:
        """Fit from a clamped static ramp (`t, f_des, f_ee`); returns self."""
        m = ramp_measures(ramp)
        self.coulomb_ = m.hysteresis / 2
        self.gain_positive_ = m.gain_positive
        self.gain_negative_ = m.gain_negative
        return self

    def as_array(self) -> np.ndarray:
        """(enabled, coulomb, gain_pos, gain_neg), the kernel's compensation vector."""
        comp = np.empty(COMPENSATION_SIZE)
        comp[COMP_ON], comp[COMP_COULOMB] = 1.0, self.coulomb_
        comp[COMP_GAIN_POS], comp[COMP_GAIN_NEG] = self.gain_positive_, self.gain_negative_
        return comp

    def to_dict(self) -> dict[str, float]:
        return {
            "coulomb": self.coulomb_,
            "gain_positive": self.gain_positive_,
            "gain_negative": self.gain_negative_,
        }


NO_COMPENSATION = np.empty(COMPENSATION_SIZE)
NO_COMPENSATION[COMP_ON], NO_COMPENSATION[COMP_COULOMB] = 0.0, 0.0
NO_COMPENSATION[COMP_GAIN_POS], NO_COMPENSATION[COMP_GAIN_NEG] = 1.0, 1.0
"""The kernel's compensation vector with the compensator off."""
