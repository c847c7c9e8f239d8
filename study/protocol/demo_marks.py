"""Whether a database holds a demo, and whether it is complete: audit rows on the demo
study, written by `study.protocol.demo` when it starts (with its options) and when it
has finished. Apart from the demo itself, so that `study schedule` can say a demo is
incomplete without loading the simulation."""

from __future__ import annotations

from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

STARTED = "started"
COMPLETE = "complete"


def mark_demo(engine: Engine, state: str, detail: str) -> None:
    """An audit row on the demo study: it was started (with its options), or finished."""
    # lazy: db.models.audit (with sqlalchemy) costs 82 ms at start-up
    from db.models.audit import AuditEntry

    # lazy: study.protocol.roster (with sqlalchemy) costs 0.1 s at start-up
    from study.protocol.roster import load_study

    with Session(engine) as session, session.begin():
        study, _ = load_study(session)
        session.add(
            AuditEntry(
                entity="study",
                entity_id=study.id,
                field="demo",
                old_value=None,
                new_value=state,
                reason=detail,
                actor="study demo",
            )
        )


def demo_state(engine: Engine) -> tuple[str, str] | None:
    """(state, detail) of the demo in the database: `started` with the options it was
    started with (until it is complete: an incomplete demo, e.g. one killed halfway) or
    `complete`; None for a database without a demo study (empty, or another study)."""
    # lazy: db.models.audit (with sqlalchemy) costs 82 ms at start-up
    from db.models.audit import AuditEntry

    with Session(engine) as session:
        row = session.execute(
            select(AuditEntry.new_value, AuditEntry.reason)
            .where(AuditEntry.entity == "study", AuditEntry.field == "demo")
            .order_by(AuditEntry.id.desc())
            .limit(1)
        ).first()
    return None if row is None else (str(row[0]), str(row[1] or ""))
