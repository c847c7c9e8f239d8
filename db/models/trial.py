"""Trials (one row per attempt) and their sample streams.

A trial row is created `scheduled`, becomes `running` when a session starts it, and
ends `completed`, `interrupted` (the process died or the operator closed the app) or
`aborted` (stopped on purpose). Repeating an interrupted trial adds a new row with
`attempt + 1`; the interrupted record and its samples stay.

A trial's summary measures are rows of `trial_measures` under the task's own names
(`peak_proximal_force_n` for LCCA, `peak_force_demanded_n` for NOTES, whatever a new
task declares, `study.protocol.tasks`); `completion_time_s` and `success`, which every
task has, are columns of the trial. `Trial.measure_values` reads and writes them as a
dict.

Samples are stored per committed chunk (at most a second of trial time), one row of
`sample_chunks` holding the chunk's columns compressed (`db.sample_codec`) in the
Arrow schema its writer was given (a row of `sample_schemas`: the trial's task's own
columns, each with its unit and description); each sample has a sequence number within
its trial. The database stores bytes and schemas: it knows no task and no loop. Written
by `db.samples.SampleWriter`, read by `db.sample_reader`.
"""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import (
    BigInteger,
    CheckConstraint,
    ForeignKey,
    Index,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.ext.associationproxy import AssociationProxy, association_proxy
from sqlalchemy.orm import Mapped, attribute_keyed_dict, mapped_column, relationship

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
    success: Mapped[bool | None]
    invalid_reason: Mapped[str | None] = mapped_column(Text)
    """Why a completed trial was marked invalid (kept, left out of the analysis); empty
    while it is valid."""
    summary: Mapped[dict[str, Any] | None]
    """Further values of the trial (seed, sample count, what a simulated participant
    noticed), SI units in the key names; the measures are in `measures`."""

    participant: Mapped[Participant] = relationship(back_populates="trials")
    block: Mapped[ScheduleBlock | None] = relationship(back_populates="trials")
    measures: Mapped[dict[str, TrialMeasure]] = relationship(
        collection_class=attribute_keyed_dict("name"),
        cascade="all, delete-orphan",
        passive_deletes=True,
        lazy="selectin",
    )
    measure_values: AssociationProxy[dict[str, float]] = association_proxy(
        "measures", "value", creator=lambda name, value: TrialMeasure(name=name, value=value)
    )
    """The trial's measures by name (read and write)."""


class TrialMeasure(Base):
    """One summary measure of a trial, under its task's name for it."""

    __tablename__ = "trial_measures"

    trial_id: Mapped[int] = mapped_column(
        ForeignKey("trials.id", ondelete="CASCADE"), primary_key=True, autoincrement=False
    )
    name: Mapped[str] = mapped_column(String(64), primary_key=True)
    value: Mapped[float]


class SampleSchema(Base):
    """The Arrow schema of stored chunks (each distinct schema once): its fields are a
    task's sample columns, with their units and descriptions in the fields' metadata."""

    __tablename__ = "sample_schemas"

    id: Mapped[int] = mapped_column(primary_key=True)
    fingerprint: Mapped[str] = mapped_column(String(64), unique=True)
    """SHA-256 of `data`, hex: the same schema is stored once."""
    data: Mapped[bytes] = mapped_column(LargeBinary)
    """The schema as an Arrow IPC schema message (`pyarrow.ipc.read_schema`)."""


class SampleChunk(Base):
    """One committed chunk of a trial's sample stream (at most a second of trial time).

    The samples are `data`, a compressed Arrow record batch of the schema `schema_id`
    names (the format is described in `db.sample_codec`); sample `k` of the chunk has sequence
    number `first_seq + k`. `t_first_s`/`t_last_s` let a reader skip chunks outside a
    time range without decoding them. Written by `db.samples.SampleWriter`, read by
    `db.sample_reader`.
    """

    __tablename__ = "sample_chunks"

    trial_id: Mapped[int] = mapped_column(
        ForeignKey("trials.id", ondelete="CASCADE"),
        primary_key=True,
        autoincrement=False,
    )
    first_seq: Mapped[int] = mapped_column(BigInteger, primary_key=True, autoincrement=False)
    """Sequence number of the chunk's first sample (0 for a trial's first)."""
    n_samples: Mapped[int]
    t_first_s: Mapped[float]
    """Time of the chunk's first sample since the trial started, s."""
    t_last_s: Mapped[float]
    """Time of its last sample, s."""
    raw_bytes: Mapped[int]
    """Size of `data` before compression, bytes."""
    schema_id: Mapped[int] = mapped_column(ForeignKey("sample_schemas.id"))
    """The Arrow schema of `data` (`SampleSchema`)."""
    data: Mapped[bytes] = mapped_column(LargeBinary)

    __table_args__ = (CheckConstraint("n_samples > 0", name="chunk_not_empty"),)
