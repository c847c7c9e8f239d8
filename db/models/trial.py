"""Trials (one row per attempt) and their sample streams.

A trial row is created `scheduled`, becomes `running` when a session starts it, and
ends `completed`, `interrupted` (the process died or the operator closed the app) or
`aborted` (stopped on purpose). Repeating an interrupted trial adds a new row with
`attempt + 1`; the interrupted record and its samples stay.

Samples are one row per sample, keyed by (trial, sequence number), with SI columns.
They are written by `db.samples.SampleWriter` in committed chunks; the ORM class here
is for reading and for the schema, not for the write path.
"""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import (
    BigInteger,
    CheckConstraint,
    ForeignKey,
    Index,
    String,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column, relationship

from db.base import Base, utcnow

if TYPE_CHECKING:
    from db.models.study import Participant, ScheduleBlock

TRIAL_STATUSES = ("scheduled", "running", "completed", "interrupted", "aborted")

_status_list = ", ".join(f"'{s}'" for s in TRIAL_STATUSES)


class Trial(Base):
    __tablename__ = "trials"
    __table_args__ = (
        UniqueConstraint("participant_id", "block_index", "practice", "trial_index", "attempt"),
        Index(None, "participant_id", "status"),
        CheckConstraint(f"status IN ({_status_list})", name="status_known"),
        CheckConstraint("trial_index >= 0", name="trial_index_nonneg"),
        CheckConstraint("attempt >= 1", name="attempt_positive"),
        CheckConstraint("completion_time_s >= 0", name="completion_time_nonneg"),
        CheckConstraint("peak_proximal_force_n >= 0", name="peak_proximal_nonneg"),
        CheckConstraint("peak_distal_force_n >= 0", name="peak_distal_nonneg"),
        CheckConstraint("wall_contacts >= 0", name="wall_contacts_nonneg"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    participant_id: Mapped[int] = mapped_column(ForeignKey("participants.id", ondelete="CASCADE"))
    block_id: Mapped[int | None] = mapped_column(
        ForeignKey("schedule_blocks.id", ondelete="SET NULL")
    )
    """Schedule block; empty for trials imported without a schedule."""
    task: Mapped[str] = mapped_column(String(16))
    condition: Mapped[str] = mapped_column(String(16))
    block_index: Mapped[int]
    trial_index: Mapped[int]
    practice: Mapped[bool] = mapped_column(default=False)
    attempt: Mapped[int] = mapped_column(default=1)
    driver: Mapped[str | None] = mapped_column(String(16))
    """Who drove: `simulated`, `keyboard`, `hardware`, or `imported`."""
    status: Mapped[str] = mapped_column(String(16), default="scheduled")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    ended_at: Mapped[datetime | None]
    completion_time_s: Mapped[float | None]
    peak_proximal_force_n: Mapped[float | None]
    peak_distal_force_n: Mapped[float | None]
    success: Mapped[bool | None]
    wall_contacts: Mapped[int | None]
    summary: Mapped[dict[str, Any] | None]
    """Further task-specific summary measures (SI units in the key names)."""

    participant: Mapped[Participant] = relationship(back_populates="trials")
    block: Mapped[ScheduleBlock | None] = relationship(back_populates="trials")


SAMPLE_COLUMNS = (
    "t_s",
    "insertion_m",
    "rotation_rad",
    "tip_x_m",
    "tip_y_m",
    "tip_z_m",
    "branch",
    "proximal_force_n",
    "proximal_force_est_n",
    "distal_force_n",
    "dial_angle_rad",
    "dial_torque_n_m",
)
"""Value columns of `samples`, in table order (the key `trial_id, seq` comes first)."""


class Sample(Base):
    """One sample of a trial's stream. Columns a task does not produce stay NULL."""

    __tablename__ = "samples"

    trial_id: Mapped[int] = mapped_column(
        ForeignKey("trials.id", ondelete="CASCADE"),
        primary_key=True,
        autoincrement=False,
    )
    seq: Mapped[int] = mapped_column(BigInteger, primary_key=True, autoincrement=False)
    t_s: Mapped[float]
    """Time since the trial started, s."""
    insertion_m: Mapped[float | None]
    rotation_rad: Mapped[float | None]
    tip_x_m: Mapped[float | None]
    tip_y_m: Mapped[float | None]
    tip_z_m: Mapped[float | None]
    branch: Mapped[str | None] = mapped_column(String(16))
    proximal_force_n: Mapped[float | None]
    """True proximal insertion force (simulation) or reference sensor, N."""
    proximal_force_est_n: Mapped[float | None]
    """Proximal force estimated from the motor current, N."""
    distal_force_n: Mapped[float | None]
    dial_angle_rad: Mapped[float | None]
    dial_torque_n_m: Mapped[float | None]
