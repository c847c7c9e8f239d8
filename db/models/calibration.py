"""Results of the calibration loop (fit, residual, added effects) kept with the study.

A calibration belongs to a device model (`follower`, `master`, `notes-translation`,
`notes-rotation`), not to a participant; `study_id` links it to a study when it was
run for one. The report is stored whole; the headline errors are columns so that a
study can list its calibrations without parsing JSON.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import CheckConstraint, ForeignKey, String
from sqlalchemy.orm import Mapped, mapped_column

from db.base import Base, utcnow


class Calibration(Base):
    __tablename__ = "calibrations"
    __table_args__ = (
        CheckConstraint("rmse_before >= 0", name="rmse_before_nonneg"),
        CheckConstraint("rmse_after >= 0", name="rmse_after_nonneg"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int | None] = mapped_column(ForeignKey("studies.id", ondelete="SET NULL"))
    model: Mapped[str] = mapped_column(String(32))
    recording_name: Mapped[str] = mapped_column(String(255))
    recording_sha256: Mapped[str] = mapped_column(String(64))
    rmse_before: Mapped[float | None]
    """Held-out RMSE of the base model, in the recording's output unit (N or N m)."""
    rmse_after: Mapped[float | None]
    report: Mapped[dict[str, Any]]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
