"""Calibration against measured data: residual -> missing effect -> better model.

`Calibrator(model).fit(data)` runs the loop of `loop.py` over a base model of
`models.py` and the effect library of `effects.py`; `fitting.CalibratedModel` is the
result the estimator can use; `synthetic.py` makes recordings with undeclared effects.
"""

from teleop_core.calibration.effects import EFFECTS, FAMILIES
from teleop_core.calibration.fitting import CalibratedModel
from teleop_core.calibration.loop import Calibrator
from teleop_core.calibration.models import CalibrationData, FollowerBase, MasterBase
from teleop_core.calibration.notes import NotesBase
from teleop_core.calibration.registry import BASE_MODELS

__all__ = [
    "BASE_MODELS",
    "EFFECTS",
    "FAMILIES",
    "CalibratedModel",
    "CalibrationData",
    "Calibrator",
    "FollowerBase",
    "MasterBase",
    "NotesBase",
]
