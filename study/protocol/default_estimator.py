"""The force estimator simulated sessions use unless told otherwise.

`study/models/follower_estimator/` ships an estimator trained on the simulated drive
(made with `study estimator train` on the follower bench's training recording; its
`summary.json` says how). Simulated trials need one because the dial renders the
estimate, not the true force, as on the paper's sensorless robot.
"""

from __future__ import annotations

from pathlib import Path

from study.errors import StudyInputError
from teleop_core.estimation.estimator import MODEL_FILES, ForceEstimator

DEFAULT_MODEL_DIR = Path(__file__).resolve().parent.parent / "models" / "follower_estimator"


def load_estimator(model_dir: Path | None = None) -> ForceEstimator:
    """The estimator in `model_dir`, or the shipped one, checked to run in the loop
    (one sample at a time) before any simulation is prepared."""
    folder = model_dir or DEFAULT_MODEL_DIR
    missing = [name for name in MODEL_FILES if not (folder / name).is_file()]
    if missing:
        raise StudyInputError(
            f"estimator folder {folder} lacks {', '.join(missing)}; expected a folder "
            "written by `study estimator train`"
        )
    estimator = ForceEstimator.load(folder)
    estimator.check_streams()
    return estimator
