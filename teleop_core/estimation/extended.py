"""The physics stage extended by a calibration: eq. 1 plus the effects found.

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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError
from teleop_core.follower.physics import REGRESSORS, PhysicsParams, from_coefficients
from teleop_core.follower.recording import FollowerRecording

if TYPE_CHECKING:
    from teleop_core.calibration.fitting import CalibratedModel

# The calibration package (and scipy.signal under it, about 1 s) is imported only where a
# calibrated model is read or run, not by every process that loads the estimator.


STAGES = ("physics", "hybrid")


@dataclass
class ExtendedPhysics:
    """A calibrated follower model as the estimator's physics stage."""

    calibrated: CalibratedModel
    base: PhysicsParams
    """Eq. 1's parameters as refitted together with the effects."""
    source: str = ""
    """Where the calibration came from (the report's file name)."""
    stage: str = "physics"
    """Where the effects stand: `physics` (a `study calibrate` report given to training:
    they replace eq. 1, and F_physics is the calibrated model) or `hybrid` (found by
    training itself, `find_effects`: F_physics stays eq. 1 fitted alone, and the effects
    are the first, physical part of the correction that the GRU completes)."""
    t_origin_s: float | None = None
    """The training recording's first time stamp, when known: an effect of the time
    since the start (drift) counts from it on a later recording of the same clock (the
    rest of a recording), and from that recording's own start otherwise."""

    @property
    def families(self) -> list[str]:
        return [effect.family for effect, _ in self.calibrated.chain]

    def force(self, recording: FollowerRecording) -> Float1D:
        """F_physics (N) over every sample: eq. 1 plus the calibrated effects."""
        # lazy: teleop_core.calibration.models costs 0.9 s at start-up
        from teleop_core.calibration.models import FollowerBase

        model = self.calibrated.model
        if not isinstance(model, FollowerBase):  # pragma: no cover - from_dict checks it
            raise TeleopInputError("the calibration is not of the follower model")
        origin = self.t_origin_s
        if origin is None or not recording.t[0] > origin:
            return self.calibrated.predict(model.data(recording))
        # a later part of the training's clock: one sample (a copy of the first) at the
        # origin, so that time since the start counts from there; its estimate is dropped
        first = recording.slice(0, 1)

        def joined_column(k: str) -> Float1D:
            return np.concatenate(
                [[origin] if k == "t" else getattr(first, k), getattr(recording, k)]
            )

        joined = FollowerRecording(
            joined_column("t"),
            joined_column("iq"),
            joined_column("theta"),
            joined_column("omega"),
            joined_column("f_ref"),
            joined_column("alpha"),
            name=recording.name,
        )
        return self.calibrated.predict(model.data(joined))[1:]

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "stage": self.stage,
            "t_origin_s": self.t_origin_s,
            "calibrated_model": self.calibrated.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "") -> ExtendedPhysics:
        """From a `study calibrate` report (or `to_dict`'s output)."""
        # lazy: teleop_core.calibration.fitting costs 0.9 s at start-up
        from teleop_core.calibration.fitting import CalibratedModel

        # lazy: teleop_core.calibration.models costs 0.9 s at start-up
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
        stage = d.get("stage", "physics")
        if stage not in STAGES:
            raise TeleopInputError(
                f"calibration {source or 'report'} has stage {stage!r}; expected one of "
                + ", ".join(STAGES)
            )
        origin = d.get("t_origin_s")
        return cls(
            calibrated,
            base,
            d.get("source", source),
            stage,
            None if origin is None else float(origin),
        )

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


def find_effects(
    recording: FollowerRecording,
    *,
    wheel_radius_m: float,
    held_out_fraction: float = 0.25,
) -> tuple[ExtendedPhysics | None, dict[str, Any]]:
    """Look for the effects eq. 1 lacks in a training recording: the
    calibration loop of `study calibrate --model follower` (its library of physical
    effects and the undeclared terms it discovers, each kept only when it cuts the error
    of a chronologically held-out end of the recording), run by training itself.

    A window of [I_q, theta_d, theta_dd] cannot see an effect that depends on time since
    the start (a winding heating up) or on a long history, so a GRU cannot learn it, and
    what it learns of a slow effect does not carry past the end of its training data;
    a physical term with its parameter fitted does. Returns the effects as the hybrid
    stage's first part (None when the loop adds none) and the loop's report.
    """
    # lazy: teleop_core.calibration.loop (with scipy, statsmodels, numpy) costs 0.9 s at start-up
    from teleop_core.calibration.loop import Calibrator

    # lazy: teleop_core.calibration.models (with scipy, statsmodels, numpy) costs 0.9 s at start-up
    from teleop_core.calibration.models import FollowerBase

    model = FollowerBase(wheel_radius_m=wheel_radius_m)
    calibrator = Calibrator(model, held_out_fraction=held_out_fraction)
    report = calibrator.fit(model.data(recording)).report()
    if not report["effects_added"] and not report["discovered_terms"]:
        return None, report
    found = ExtendedPhysics.from_dict(report, "found in training")
    return replace(found, stage="hybrid", t_origin_s=float(recording.t[0])), report
