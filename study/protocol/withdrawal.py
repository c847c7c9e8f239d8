"""Withdrawing a participant, a note per participant, the session checklist.

A participant who withdraws is kept, not deleted: their trials, samples and
questionnaires stay in the database and in every export, the participant is marked
(`withdrawn_at`, `withdrawal_reason`), no further session runs for them, and the analysis
leaves them out and lists them with the reason among its exclusions. Each change is an
audit row with its actor and reason. A note is free text for the experimenter (no
personal data: the codes are the only identity the database holds).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.base import utcnow
from db.models.audit import AuditEntry
from db.models.study import Participant
from study.errors import StudyInputError
from study.protocol.actor import current_actor
from study.protocol.free_text import check_free_text
from study.protocol.roster import find_participant, load_study

Change = tuple[Participant, Callable[[str, "str | None", str, str], None]]
"""A participant being changed and audit(field, old, new, reason), which logs a change."""


def _check_text(what: str, text: str) -> str:
    return check_free_text(what, text)


@contextmanager
def _audited_change(engine: Engine, code: str, actor: str | None) -> Iterator[Change]:
    """One transaction on participant `code` (a one-line error if unknown) whose audit
    rows name `actor` (`current_actor` by default)."""
    who = current_actor(actor)
    with Session(engine) as session, session.begin():
        study, _ = load_study(session)
        p = find_participant(session, study, code)

        def audit(field: str, old: str | None, new: str, reason: str) -> None:
            session.add(
                AuditEntry(
                    entity="participant",
                    entity_id=p.id,
                    field=field,
                    old_value=old,
                    new_value=new,
                    reason=reason,
                    actor=who,
                )
            )

        yield p, audit


def withdraw(engine: Engine, code: str, reason: str, actor: str | None = None) -> None:
    """Mark `code` withdrawn with `reason`; one-line errors for an unknown or withdrawn one."""
    reason = _check_text("withdrawal reason", reason)
    with _audited_change(engine, code, actor) as (p, audit):
        if p.withdrawn_at is not None:
            raise StudyInputError(
                f"participant {code} withdrew on {p.withdrawn_at:%Y-%m-%d} "
                f"({p.withdrawal_reason}); expected an enrolled participant"
            )
        p.withdrawn_at = utcnow()
        p.withdrawal_reason = reason
        audit("status", "enrolled", "withdrawn", reason)


def set_note(engine: Engine, code: str, note: str, actor: str | None = None) -> None:
    """Replace `code`'s note (the old one goes into the audit log)."""
    note = _check_text("note", note)
    with _audited_change(engine, code, actor) as (p, audit):
        audit("note", p.note, note, "note edited")
        p.note = note


def add_session_note(engine: Engine, code: str, note: str, actor: str | None = None) -> None:
    """A note on `code`'s session (today's): kept beside the participant's note as an
    audit row `session_note`, one per call, never replaced."""
    note = _check_text("session note", note)
    with _audited_change(engine, code, actor) as (_, audit):
        audit("session_note", None, note, f"note on the session of {utcnow():%Y-%m-%d}")


CHECKLIST = "consent confirmed; device checked"


def record_checklist(engine: Engine, code: str, actor: str | None = None) -> None:
    """The operator confirmed the session checklist before `code`'s session: an audit row."""
    with _audited_change(engine, code, actor) as (_, audit):
        audit("session_checklist", None, CHECKLIST, "confirmed before the session's first trial")


def withdrawn_participants(engine: Engine) -> dict[str, str]:
    """Code -> withdrawal reason, for every withdrawn participant."""
    with Session(engine) as session:
        rows = session.execute(
            select(Participant.code, Participant.withdrawal_reason).where(
                Participant.withdrawn_at.is_not(None)
            )
        ).all()
    return {code: reason or "" for code, reason in rows}
