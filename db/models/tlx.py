"""NASA-TLX questionnaires: one per participant x task x condition block.

Ratings are integers 0..100 in steps of 5 (the paper form's 21 marks), enforced by
CHECK constraints so that no path into the database, the ORM or raw SQL, can store an
off-scale value. Weights are the tallies of the 15 pairwise comparisons (each 0..5,
all present and summing to 15, or all absent for a raw-TLX-only questionnaire). The
choices themselves, in the order they were presented, are kept in `pairwise`.
"""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import CheckConstraint, ForeignKey, String, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column, relationship

from db.base import Base, utcnow
from db.tlx_subscales import TLX_SUBSCALES

if TYPE_CHECKING:
    from db.models.study import Participant


_rating_checks = tuple(
    CheckConstraint(f"{s} BETWEEN 0 AND 100 AND {s} % 5 = 0", name=f"{s}_on_scale")
    for s in TLX_SUBSCALES
)
_weight_checks = tuple(
    CheckConstraint(f"w_{s} BETWEEN 0 AND 5", name=f"w_{s}_range") for s in TLX_SUBSCALES
)
_all_null = " AND ".join(f"w_{s} IS NULL" for s in TLX_SUBSCALES)
_none_null = " AND ".join(f"w_{s} IS NOT NULL" for s in TLX_SUBSCALES)
_sum = " + ".join(f"w_{s}" for s in TLX_SUBSCALES)
_weights_complete = CheckConstraint(
    f"({_all_null}) OR ({_none_null} AND {_sum} = 15)", name="weights_sum_15"
)


class TlxResponse(Base):
    __tablename__ = "tlx_responses"
    __table_args__ = (
        UniqueConstraint("participant_id", "task", "condition"),
        *_rating_checks,
        *_weight_checks,
        _weights_complete,
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    participant_id: Mapped[int] = mapped_column(ForeignKey("participants.id", ondelete="CASCADE"))
    task: Mapped[str] = mapped_column(String(16))
    condition: Mapped[str] = mapped_column(String(16))
    mental: Mapped[int]
    physical: Mapped[int]
    temporal: Mapped[int]
    performance: Mapped[int]
    effort: Mapped[int]
    frustration: Mapped[int]
    w_mental: Mapped[int | None]
    w_physical: Mapped[int | None]
    w_temporal: Mapped[int | None]
    w_performance: Mapped[int | None]
    w_effort: Mapped[int | None]
    w_frustration: Mapped[int | None]
    pairwise: Mapped[list[Any] | None]
    """The 15 comparisons as presented: `[[left, right, chosen], ...]`."""
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime | None]

    participant: Mapped[Participant] = relationship(back_populates="tlx_responses")
