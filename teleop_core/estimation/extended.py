"""The physics stage extended by a calibration (issue 10): eq. 1 plus the effects found.

`ExtendedPhysics` wraps the calibrated follower model of a `study calibrate` report:
its `force` replaces eq. 1 in the estimator's physics stage, so the GRU is trained on
(and corrects) only what the calibrated model still misses; `base` gives eq. 1's
refitted parameters, which the EKF keeps using for its Jacobian (the effects are
corrections to the force it fuses, not new states).

The effects may need more than the streaming window's [I_q, theta_d, theta_dd] (the
wheel angle, the time since the start, the history of the current), so an extended
estimator runs over whole recordings (`ForceEstimator.predict`); `stream()` refuses it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError
from teleop_core.follower.physics import REGRESSORS, PhysicsParams, from_coefficients
from teleop_core.follower.recording import FollowerRecording

if TYPE_CHECKING:
    from teleop_core.calibration.fitting import CalibratedModel

# The calibration package (and scipy.signal under it, about 1 s) is imported only where a
# calibrated model is read or run, not by every process that loads the estimator.


@dataclass
class ExtendedPhysics:
    """A calibrated follower model as the estimator's physics stage."""

    calibrated: CalibratedModel
    base: PhysicsParams
    """Eq. 1's parameters as refitted together with the effects."""
    source: str = ""
    """Where the calibration came from (the report's file name)."""

    @property
    def families(self) -> list[str]:
        return [effect.family for effect, _ in self.calibrated.chain]

    def force(self, recording: FollowerRecording) -> Float1D:
        """F_physics (N) over every sample: eq. 1 plus the calibrated effects."""
        from teleop_core.calibration.models import FollowerBase

        model = self.calibrated.model
        if not isinstance(model, FollowerBase):  # pragma: no cover - from_dict checks it
            raise TeleopInputError("the calibration is not of the follower model")
        return self.calibrated.predict(model.data(recording))

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "calibrated_model": self.calibrated.to_dict()}

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "") -> ExtendedPhysics:
        """From a `study calibrate` report (or `to_dict`'s output)."""
        from teleop_core.calibration.fitting import CalibratedModel
        from teleop_core.calibration.models import FollowerBase

        if "calibrated_model" not in d:
            raise TeleopInputError(
                f"calibration {source or 'report'} has no 'calibrated_model'; expected the "
                "--json report of `study calibrate`"
            )
        calibrated = CalibratedModel.from_dict(d["calibrated_model"])
        if not isinstance(calibrated.model, FollowerBase):
            raise TeleopInputError(
                f"calibration {source or 'report'} is of the {calibrated.model.name!r} model; "
                "the force estimator needs --model follower"
            )
        # F = (K_t I_q - J a - b w - tau_c sgn w) / r + F_0: the first five coefficients
        # with the sign width the calibration fitted (the estimator's 0.3 rad/s in a
        # calibration made before it was fitted)
        base = from_coefficients(
            calibrated.coef[:REGRESSORS],
            calibrated.model.wheel_radius_m,
            calibrated.model.sign_width_rad_s,
        )
        return cls(calibrated, base, d.get("source", source))

    @classmethod
    def read(cls, path: str | Path) -> ExtendedPhysics:
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except FileNotFoundError:
            raise TeleopInputError(f"calibration report {path} does not exist") from None
        except json.JSONDecodeError as exc:
            raise TeleopInputError(f"calibration report {path} is not valid JSON: {exc}") from None
        return cls.from_dict(d, source=path.name)


def physics_force(
    physics: PhysicsParams, extension: ExtendedPhysics | None, recording: FollowerRecording
) -> Float1D:
    """The physics stage over a recording: eq. 1, or the calibrated model when given."""
    if extension is not None:
        return extension.force(recording)
    return physics.force(recording.iq, recording.omega, recording.alpha)
