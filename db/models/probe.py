"""Probe trials: one row per participant x probe x trial.

A probe (a short psychophysical measurement before a task's first block, `study.probes`)
stores its stimulus and the answer as plain numbers in its own SI units, whether a
forced choice was right, and the settings its measurement model needs (`context`, e.g.
the dial's haptic gain). `db` knows no probe: the names and units are the probe's.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import CheckConstraint, ForeignKey, String, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from db.base import Base, utcnow


class ProbeTrial(Base):
    __tablename__ = "probe_trials"
    __table_args__ = (
        UniqueConstraint("participant_id", "probe", "trial_index"),
        CheckConstraint("trial_index >= 0", name="trial_index_nonneg"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    participant_id: Mapped[int] = mapped_column(
        ForeignKey("participants.id", ondelete="CASCADE"), index=True
    )
    probe: Mapped[str] = mapped_column(String(32))
    trial_index: Mapped[int]
    stimulus: Mapped[float | None]
    response: Mapped[float | None]
    """None: no answer (a device trial that timed out)."""
    correct: Mapped[bool | None]
    context: Mapped[dict[str, Any]]
    driver: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
