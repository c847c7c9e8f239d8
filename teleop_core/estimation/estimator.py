"""The force estimator end to end: physics (eq. 1) -> GRU residual (eqs. 3-4) -> EKF.

The public face of the estimator (split along its seams): the model and its
folder (`ForceEstimator`, `CausalEstimator`) are in `model.py`, the streaming steps the
loop kernel calls in `stream.py`, training in `training.py` (imported from there: it
imports PyTorch, which running a trained estimator does not need, and `model.py`).
"""

from __future__ import annotations

from teleop_core.estimation.model import (
    MODEL_FILES,
    RATE_TOLERANCE,
    CausalEstimator,
    EstimateResult,
    ForceEstimator,
    features_of,
    inputs_of,
)
from teleop_core.estimation.stream import (
    EST_FINAL,
    EST_HYBRID,
    EST_PHYSICS,
    ESTIMATE_OUT,
    STREAM_STATE_SIZE,
    stream_estimate,
    stream_push,
)

__all__ = [
    "ESTIMATE_OUT",
    "EST_FINAL",
    "EST_HYBRID",
    "EST_PHYSICS",
    "MODEL_FILES",
    "RATE_TOLERANCE",
    "STREAM_STATE_SIZE",
    "CausalEstimator",
    "EstimateResult",
    "ForceEstimator",
    "features_of",
    "inputs_of",
    "stream_estimate",
    "stream_push",
]
