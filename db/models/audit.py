"""Append-only audit log of edits to questionnaires and trial status.

Every change to a stored value a researcher may later have to justify (a TLX rating
corrected, a trial marked interrupted or aborted) leaves one row per changed field
with the old and the new value as text. Nothing in the application updates or
deletes audit rows.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import Index, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from db.base import Base, utcnow


class AuditEntry(Base):
    __tablename__ = "audit_log"
    __table_args__ = (Index(None, "entity", "entity_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    at: Mapped[datetime] = mapped_column(default=utcnow)
    entity: Mapped[str] = mapped_column(String(32))
    """Table of the changed row, e.g. `tlx_responses` or `trials`."""
    entity_id: Mapped[int]
    field: Mapped[str] = mapped_column(String(64))
    old_value: Mapped[str | None] = mapped_column(Text)
    new_value: Mapped[str | None] = mapped_column(Text)
    reason: Mapped[str | None] = mapped_column(Text)
    actor: Mapped[str | None] = mapped_column(String(64))
    """Who made the change: an experimenter code or the host name, never a person's name."""
