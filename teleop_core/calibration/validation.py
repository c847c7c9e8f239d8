"""A calibrated model on recordings it was not fitted to: validation on another experiment.

Identification practice fits on one experiment and validates on another (another
trajectory, speed or day): the question a user asks before trusting a model is how it
does on data it never saw, which a held-out end of the same recording answers only
for that recording's conditions. `validate` runs the model the loop calibrated (the
base model and every effect added, each with the coefficients and searched values
fitted on the training recording, nothing refitted) over every sample of another
recording, as MATLAB's `compare` simulates a model over a validation data set.

The base models are inverse models: they predict the force (or torque) from the
recorded drive and motion, never from the measured force, so the prediction over the
whole recording is the model's simulation from that recording's own inputs. Effects
with memory (a hysteresis loop, a backlash, a drift, a delay) start from the
recording's first sample: the state a model has at the start of an experiment is
what the experiment's first samples give it. A `gain_change` term keeps its change
time on the recording's own clock.

The fit is MATLAB `compare`'s NRMSE fit (`verdict.fit_percent`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from teleop_core._typing import Float1D
from teleop_core.calibration.fitting import CalibratedModel
from teleop_core.calibration.models import CalibrationData
from teleop_core.calibration.verdict import fit_percent


@dataclass(frozen=True)
class Validation:
    """How a calibrated model predicts one validation recording, over all its samples."""

    recording: str
    """The recording as the user named it (its path)."""
    rmse_base: float
    """RMSE of the base model fitted on the training recording, output units."""
    rmse_final: float
    """RMSE of the calibrated model (base and every effect added), output units."""
    fit_percent: float
    """NRMSE fit of the calibrated model, %: 100 (1 - ||y - y_hat|| / ||y - mean(y)||)."""
    samples: int
    """Samples predicted: the whole recording."""
    t: Float1D = field(repr=False)
    """Time, s, shape (n,)."""
    measured: Float1D = field(repr=False)
    """The recording's measured output, shape (n,)."""
    base: Float1D = field(repr=False)
    """The base model's prediction, shape (n,)."""
    final: Float1D = field(repr=False)
    """The calibrated model's prediction, shape (n,)."""

    def to_dict(self) -> dict[str, Any]:
        """The report's entry: `recording`, `rmse_base`, `rmse_final`, `fit_percent`,
        `samples`."""
        return {
            "recording": self.recording,
            "rmse_base": self.rmse_base,
            "rmse_final": self.rmse_final,
            "fit_percent": self.fit_percent,
            "samples": self.samples,
        }


def validate(
    base: CalibratedModel, final: CalibratedModel, data: CalibrationData, recording: str
) -> Validation:
    """Predict every sample of `data` with the base and the calibrated model.

    Parameters
    ----------
    base, final : CalibratedModel
        The base model alone and the calibrated model, both fitted on the training
        recording (`Calibrator.base_model_`, `Calibrator.model_`).
    data : CalibrationData
        The validation recording, read as the training one was (for the rigid axis,
        with the training recording's derivative cutoff: `BaseModel.reader_for`).
    recording : str
        Its name in the report (the path given).

    Returns
    -------
    Validation
        The two RMSEs, the calibrated model's fit and the predictions.

    Examples
    --------
    A model that predicts the output exactly fits 100 %; one that predicts its mean, 0 %.

    >>> from teleop_core.calibration.verdict import fit_percent
    >>> fit_percent(np.array([1.0, 2.0, 3.0]), np.array([2.0, 2.0, 2.0]))
    0.0
    """
    y = np.asarray(data.y, float)
    y_base, y_final = base.predict(data), final.predict(data)
    return Validation(
        recording,
        _rmse(y - y_base),
        _rmse(y - y_final),
        fit_percent(y, y_final),
        len(y),
        np.asarray(data.signals["t"], float),
        y,
        y_base,
        y_final,
    )


def _rmse(e: Float1D) -> float:
    return float(np.sqrt(np.mean(e * e)))
