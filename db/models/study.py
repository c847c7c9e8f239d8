"""Studies, their participants and each participant's schedule of blocks.

A study keeps the design it was created from (the TOML text as written and its
validated form), so that a database is self-describing years later. Participants
are pseudonymous codes with an experience group: the database holds no names or
contact details, and `Participant.code` refuses anything that is not a code.
"""

from __future__ import annotations

import re
from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import (
    CheckConstraint,
    ForeignKey,
    Index,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column, relationship, validates

from db.base import Base, utcnow
from db.errors import DbInputError

if TYPE_CHECKING:
    from db.models.tlx import TlxResponse
    from db.models.trial import Trial

CODE_PATTERN = re.compile(r"^[A-Z]{1,4}[0-9]{2,6}$")
"""Pseudonymous participant codes: 1-4 capital letters then 2-6 digits (`P007`, `S2P013` is not)."""


class Study(Base):
    __tablename__ = "studies"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    design_toml: Mapped[str] = mapped_column(Text)
    """The design file exactly as given to `study init`."""
    design: Mapped[dict[str, Any]]
    """The validated design, with defaults filled in."""
    seed: Mapped[int]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    participants: Mapped[list[Participant]] = relationship(
        back_populates="study", order_by="Participant.id"
    )


class Participant(Base):
    __tablename__ = "participants"
    __table_args__ = (
        UniqueConstraint("study_id", "code"),
        Index(None, "study_id", "group"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"))
    code: Mapped[str] = mapped_column(String(16))
    group: Mapped[str] = mapped_column(String(32))
    """Experience group by its design name (e.g. `outsider`, `novice`, `expert`)."""
    condition_order: Mapped[list[Any]]
    """Conditions in the order this participant meets them, e.g. `["HV", "VO"]`."""
    site: Mapped[str | None] = mapped_column(String(64))
    """Lab that enrolled the participant (multi-site studies)."""
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    withdrawn_at: Mapped[datetime | None]
    """When the participant withdrew (kept, marked, left out of the analysis)."""
    withdrawal_reason: Mapped[str | None] = mapped_column(Text)
    note: Mapped[str | None] = mapped_column(Text)
    """The experimenter's note on this participant (no personal data)."""

    study: Mapped[Study] = relationship(back_populates="participants")
    blocks: Mapped[list[ScheduleBlock]] = relationship(
        back_populates="participant", order_by="ScheduleBlock.block_index"
    )
    trials: Mapped[list[Trial]] = relationship(back_populates="participant", order_by="Trial.id")
    tlx_responses: Mapped[list[TlxResponse]] = relationship(back_populates="participant")

    @validates("code")
    def _check_code(self, _key: str, code: str) -> str:
        if not CODE_PATTERN.match(code):
            raise DbInputError(
                f"participant code {code!r} is not a pseudonymous code; "
                "expected 1-4 capital letters and 2-6 digits, e.g. P007"
            )
        return code


class ScheduleBlock(Base):
    """One block of a participant's schedule: a task under one condition."""

    __tablename__ = "schedule_blocks"
    __table_args__ = (
        UniqueConstraint("participant_id", "block_index"),
        CheckConstraint("block_index >= 0", name="block_index_nonneg"),
        CheckConstraint("n_trials >= 1", name="n_trials_positive"),
        CheckConstraint("n_practice >= 0", name="n_practice_nonneg"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    participant_id: Mapped[int] = mapped_column(ForeignKey("participants.id", ondelete="CASCADE"))
    block_index: Mapped[int]
    task: Mapped[str] = mapped_column(String(16))
    condition: Mapped[str] = mapped_column(String(16))
    n_practice: Mapped[int] = mapped_column(default=0)
    n_trials: Mapped[int]
    break_after_s: Mapped[float | None]
    """Planned rest after the block, seconds."""

    participant: Mapped[Participant] = relationship(back_populates="blocks")
    trials: Mapped[list[Trial]] = relationship(back_populates="block")
