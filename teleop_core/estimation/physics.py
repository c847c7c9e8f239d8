"""Moved to `teleop_core.follower.physics`: calibration needs it too, and
calibration sits below the estimator, so it lives with the follower drive it describes.
This name is the same module object, so old imports (and monkeypatching) keep working."""

import sys

from teleop_core.follower import physics as _moved

sys.modules[__name__] = _moved
