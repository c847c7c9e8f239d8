"""Streams of the lab's other instruments recorded with a trial (Lab Streaming Layer).

An eye tracker, EMG or a second camera recorded beside the robot is stored apart from
the trial's own samples: one `lsl_streams` row per stream and trial (its name, type,
channels with units, the clocks that put its samples on the trial's time, the gaps
where it was lost), and its samples in `lsl_chunks`, each chunk a compressed Arrow
IPC stream (with its schema: every stream has its own channels) of `t_s` (time on the
trial's clock), `lsl_time_s` (the source's own time stamp) and one column per channel
under the stream's channel names. Written and read by `study.lsl.store`.

On the trial's clock, sample `k` is at
`t_s = (lsl_time_s + time_correction_s - lsl_t0_s) * clock_rate`: `time_correction_s`
brings the source's clock to the recording machine's LSL clock, `lsl_t0_s` is the
trial's start on that clock, and `clock_rate` the trial seconds per second of wall time
(1 unless the session was paced slower or faster than real time), as long as the loop
kept pace with the wall clock; where it fell behind, `t_s` is the loop's own progress
at the sample's moment (`study.lsl.record`).
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import (
    BigInteger,
    CheckConstraint,
    ForeignKey,
    LargeBinary,
    String,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column

from db.base import Base

STREAM_ORIGINS = ("live", "xdf")


class LslStream(Base):
    """One external stream recorded during one trial."""

    __tablename__ = "lsl_streams"
    __table_args__ = (
        UniqueConstraint("trial_id", "name", "source_id"),
        CheckConstraint("origin IN ('live', 'xdf')", name="origin_known"),
        CheckConstraint("clock_rate > 0", name="clock_rate_positive"),
        CheckConstraint("n_samples >= 0", name="n_samples_nonneg"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    trial_id: Mapped[int] = mapped_column(ForeignKey("trials.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(128))
    """The stream's LSL name (`EMG-Delsys`)."""
    type: Mapped[str] = mapped_column(String(64))
    """The stream's LSL content type (`EMG`, `Gaze`, `Markers`)."""
    source_id: Mapped[str] = mapped_column(String(256), default="")
    hostname: Mapped[str] = mapped_column(String(256), default="")
    channel_format: Mapped[str] = mapped_column(String(16))
    """LSL's: float32, double64, int32, string, ..."""
    nominal_srate_hz: Mapped[float]
    """The declared sampling rate, Hz; 0 for an irregular stream (markers)."""
    channels: Mapped[list[Any]]
    """[{"name", "unit", "type"}] per channel, in the stream's order (units as declared)."""
    lsl_t0_s: Mapped[float]
    """The trial's start on the recording machine's LSL clock, s."""
    time_correction_s: Mapped[float]
    """Added to the source's time stamps to bring them onto that clock, s."""
    clock_rate: Mapped[float] = mapped_column(default=1.0)
    """Trial seconds per second of LSL time."""
    origin: Mapped[str] = mapped_column(String(8))
    """`live` (recorded by the session) or `xdf` (imported from a recording)."""
    n_samples: Mapped[int] = mapped_column(default=0)
    gaps: Mapped[list[Any]] = mapped_column(default=list)
    """[[from_s, to_s]] on the trial's clock where the stream was lost."""


class LslChunk(Base):
    """A committed chunk of an external stream's samples (see the module docstring)."""

    __tablename__ = "lsl_chunks"
    __table_args__ = (CheckConstraint("n_samples > 0", name="chunk_not_empty"),)

    stream_id: Mapped[int] = mapped_column(
        ForeignKey("lsl_streams.id", ondelete="CASCADE"), primary_key=True, autoincrement=False
    )
    first_seq: Mapped[int] = mapped_column(BigInteger, primary_key=True, autoincrement=False)
    n_samples: Mapped[int]
    t_first_s: Mapped[float]
    t_last_s: Mapped[float]
    raw_bytes: Mapped[int]
    data: Mapped[bytes] = mapped_column(LargeBinary)
