"""Every base model by its `--model` name: one place that knows them all, so that the
loop, a saved calibration and the command resolve a name the same way."""

from __future__ import annotations

from teleop_core.calibration.models import BaseModel, FollowerBase, MasterBase
from teleop_core.calibration.notes import NotesBase
from teleop_core.calibration.rigid_axis import RigidAxisBase

BASE_MODELS: dict[str, BaseModel] = {
    "follower": FollowerBase(),
    "master": MasterBase(),
    "notes-translation": NotesBase("translation"),
    "notes-rotation": NotesBase("rotation"),
    "rigid-axis": RigidAxisBase(),
}
"""Base models by name (the report's `model`)."""
