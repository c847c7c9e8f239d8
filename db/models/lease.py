"""Session leases: at most one running session per participant, across processes and machines.

A session holds its participant's lease while it runs: one row keyed by the
participant (the primary key is what makes a second holder impossible on every
backend), naming the holder (host, process id, a random token) and renewed by a
heartbeat. A second session finds the row and refuses while the holder is alive; a
holder that died (its process is gone from this host, or its heartbeat is older than
the lease timeout) is replaced, and its `running` trial recovered as interrupted.
The rules live in `study.protocol.lease`; this module only declares the table.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import ForeignKey, String
from sqlalchemy.orm import Mapped, mapped_column

from db.base import Base


class SessionLease(Base):
    __tablename__ = "session_leases"

    participant_id: Mapped[int] = mapped_column(
        ForeignKey("participants.id", ondelete="CASCADE"), primary_key=True, autoincrement=False
    )
    token: Mapped[str] = mapped_column(String(32))
    """Random hex token of the holding session (a process may hold several in turn)."""
    host: Mapped[str] = mapped_column(String(255))
    """Host name of the holder's machine."""
    pid: Mapped[int]
    """Process id of the holder on `host`."""
    actor: Mapped[str | None] = mapped_column(String(64))
    """Who started the session (see `study.protocol.actor`)."""
    acquired_at: Mapped[datetime]
    heartbeat_at: Mapped[datetime]
    """Last renewal by the holder's clock (UTC); stale after the lease timeout."""
