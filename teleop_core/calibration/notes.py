"""The NOTES device's base model for calibration: the linear Fig. 8 model of [notes].

The NOTES model (`teleop_core.notes`) owns the device: its
parameters, its linear mass-spring-damper response and its recording contract
(`t, f_des, f_ee` for a clamped run). This module only puts that linear model in the
calibration loop's form: the end-effector force (or torque) is

    f_ee = g * F_lin(f_des) + c

where F_lin is the clamped response of the linear Fig. 8 model to the command
(`notes.simulate.simulate_response(..., nonlinear=False)`), g a gain and c an offset.
What the paper observed beyond it, the friction hysteresis of the static ramps and the
counter-clockwise transmission loss in rotation, is left for the loop to find: as
`hysteresis` (a play operator on the command) and `direction_asymmetry` (extra
friction and a gain change for negative commands, `direction` being F_lin).

Only clamped recordings are calibrated: the loop models a force, and an open-ended
run measures a position.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleop_core._typing import Float1D, Float2D
from teleop_core.calibration.effects import Signals
from teleop_core.calibration.models import BaseModel, CalibrationData
from teleop_core.errors import TeleopInputError
from teleop_core.notes.params import DOFS, default_params
from teleop_core.notes.recording import NotesRecording
from teleop_core.notes.simulate import simulate_response

SIGN_FRACTION = 0.02
"""Width of the smoothed sign of the command's direction, as a share of its range."""
CHIRP_HELD_OUT_BLOCKS = 8
"""Held-out blocks for a chirp: one per segment of the 1-30 Hz sweep, so that every
frequency band is tested (its end alone holds the highest frequencies only)."""


@dataclass(frozen=True)
class NotesBase(BaseModel):
    """The linear Fig. 8 model of one NOTES axis, gain and offset fitted."""

    dof: str = "translation"
    """"translation" (force, N) or "rotation" (torque, N m)."""

    families = ("hysteresis", "direction_asymmetry", "delay", "drift", "current_nonlinearity")
    plot_against = ("t", "drive")
    passive_loop_sign = -1
    """The force follows the command through the friction: lower while the command
    rises (the half loop is minus the Coulomb friction)."""

    def __post_init__(self) -> None:
        if self.dof not in DOFS:
            raise TeleopInputError(f"NOTES axis {self.dof!r}; expected one of {', '.join(DOFS)}")

    @property
    def name(self) -> str:  # type: ignore[override]
        return f"notes-{self.dof}"

    @property
    def unit(self) -> str:  # type: ignore[override]
        return "n" if self.dof == "translation" else "n_m"

    @property
    def output_unit(self) -> str:  # type: ignore[override]
        return "N" if self.dof == "translation" else "N m"

    def columns(self, s: Signals) -> Float2D:
        # f_ee = g F_lin(f_des) + c
        return np.column_stack([s["linear"], np.ones_like(s["linear"])])

    def physical(self, coef: Float1D) -> dict[str, float]:
        return {"linear_gain": coef[0], f"offset_{self.unit}": coef[1]}

    def rename(self, family: str, params: dict[str, float]) -> dict[str, float]:
        """Physical names for the NOTES device (the follower's speak of wheel speed)."""
        if family != "direction_asymmetry":
            return params
        names = list(params)
        # columns: -min(sgn(F_lin), 0) and -min(F_lin, 0); the second's coefficient is
        # the share of a negative command lost on the way (0.2 for a 0.8 transmission)
        return {f"reverse_friction_{self.unit}": params[names[0]], "reverse_loss": params[names[1]]}

    def data(self, rec: NotesRecording, name: str = "recording") -> CalibrationData:
        if rec.boundary != "clamped":
            raise TeleopInputError(
                f"{name} is an open-ended run (t, f_des, x); the NOTES calibration models "
                "the end-effector force: expected a clamped run (t, f_des, f_ee)"
            )
        linear = simulate_response(default_params(self.dof), rec.t, rec.f_des, "clamped", False)
        width = SIGN_FRACTION * max(float(np.ptp(linear)), 1e-12)
        signals = {
            "t": rec.t,
            "drive": rec.f_des,
            "linear": linear,
            "direction": linear,
            "direction_sign": np.tanh(linear / width),
        }
        blocks = CHIRP_HELD_OUT_BLOCKS if rec.experiment == "chirp" else 1
        return CalibrationData(signals, rec.y, name, held_out_blocks=blocks)

    def read(self, path: str | Path) -> CalibrationData:
        return self.data(NotesRecording.from_csv(path), Path(path).name)
