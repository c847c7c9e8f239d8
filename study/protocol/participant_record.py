"""Everything stored about one participant, for a page of its own: the schedule in its
counterbalanced order, every trial row (attempts and interrupted ones included), the
questionnaires per block, the probes, the notes and the audited changes.

`participant_record` reads it in one session (a handful of queries); the terminal app's
participant page and `study trial list` show it. Read-only: the changes are
`study.protocol.corrections` and `study.protocol.withdrawal`; a trial left `running` by
a session that is gone is shown `interrupted` (`study.protocol.orphans`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from db.models.audit import AuditEntry
from db.models.probe import ProbeTrial
from db.models.tlx import TlxResponse
from db.models.trial import Trial
from study.protocol.orphans import gone_sessions
from study.protocol.roster import find_participant, load_study
from study.protocol.tasks import get_task

__all__ = ["BlockRow", "NoteRow", "ParticipantRecord", "TrialRow", "participant_record"]


@dataclass(frozen=True)
class TrialRow:
    """One stored trial row (an attempt)."""

    id: int
    block_index: int
    task: str
    condition: str
    practice: bool
    number: int
    """1-based among the block's practice trials or among its measured trials."""
    attempt: int
    status: str
    driver: str | None
    completion_time_s: float | None
    success: bool | None
    measures: dict[str, float]
    """By name, in the order the task declares them."""
    invalid_reason: str | None
    why: str | None
    """The audit log's reason for the last status change (why it was interrupted)."""

    def label(self) -> str:
        return f"{'practice' if self.practice else 'trial'} {self.number}"


@dataclass(frozen=True)
class BlockRow:
    block_index: int
    task: str
    condition: str
    planned: int
    completed: int
    tlx: str
    """`stored`, `missing` (the block is done, no questionnaire) or `-` (not done yet)."""


@dataclass(frozen=True)
class NoteRow:
    at: datetime
    actor: str | None
    kind: str
    """`note` (the standing note as edited) or `session` (a note added to the history)."""
    text: str


@dataclass(frozen=True)
class ParticipantRecord:
    code: str
    group: str
    site: str | None
    condition_order: list[str]
    withdrawn: str | None
    note: str | None
    blocks: list[BlockRow]
    trials: list[TrialRow]
    notes: list[NoteRow]
    probes: dict[str, int]
    """Probe name -> trials stored."""
    probes_due: list[str] = field(default_factory=list)
    """The design's probes not stored yet."""

    def next_block(self) -> BlockRow | None:
        return next((b for b in self.blocks if b.completed < b.planned), None)


def _in_task_order(task: str, values: dict[str, float]) -> dict[str, float]:
    """`values` in the order the task declares its measures (a task this version does not
    know: as stored)."""

    try:
        names = [m.name for m in get_task(task).all_measures]
    except ValueError:
        names = []
    first = {n: values[n] for n in names if n in values}
    return first | {n: v for n, v in values.items() if n not in first}


def _trial_row(t: Trial, why: str | None, session_gone: str | None) -> TrialRow:
    """One trial as shown: a `running` one whose session is gone (`session_gone`, why)
    as `interrupted`, nothing written (the next session marks it)."""
    shown_gone = t.status == "running" and session_gone is not None
    return TrialRow(
        id=t.id,
        block_index=t.block_index,
        task=t.task,
        condition=t.condition,
        practice=t.practice,
        number=t.trial_index + 1,
        attempt=t.attempt,
        status="interrupted" if shown_gone else t.status,
        driver=t.driver,
        completion_time_s=t.completion_time_s,
        success=t.success,
        measures=_in_task_order(t.task, dict(t.measure_values)),
        invalid_reason=t.invalid_reason,
        why=session_gone if shown_gone else why,
    )


def participant_record(engine: Engine, code: str) -> ParticipantRecord:
    """What is stored about `code` (a one-line error for an unknown code)."""
    with Session(engine) as session:
        study, design = load_study(session)
        p = find_participant(session, study, code)
        trials = session.scalars(
            select(Trial).where(Trial.participant_id == p.id).order_by(Trial.id)
        ).all()
        # a running trial whose session is gone (kill -9) shows as interrupted
        gone = gone_sessions(session, [p.id]) if any(t.status == "running" for t in trials) else {}
        why = {
            e.entity_id: e.reason
            for e in session.scalars(
                select(AuditEntry)
                .where(
                    AuditEntry.entity == "trial",
                    AuditEntry.field == "status",
                    AuditEntry.entity_id.in_([t.id for t in trials]),
                )
                .order_by(AuditEntry.id)
            )
        }
        answered = {
            (r.task, r.condition)
            for r in session.execute(
                select(TlxResponse.task, TlxResponse.condition).where(
                    TlxResponse.participant_id == p.id
                )
            )
        }
        probes = dict(
            session.execute(
                select(ProbeTrial.probe, func.count())
                .where(ProbeTrial.participant_id == p.id)
                .group_by(ProbeTrial.probe)
                .order_by(ProbeTrial.probe)
            ).all()
        )
        notes = [
            NoteRow(
                e.at, e.actor, "session" if e.field == "session_note" else "note", e.new_value or ""
            )
            for e in session.scalars(
                select(AuditEntry)
                .where(
                    AuditEntry.entity == "participant",
                    AuditEntry.entity_id == p.id,
                    AuditEntry.field.in_(("note", "session_note")),
                )
                .order_by(AuditEntry.id)
            )
        ]
        rows = [_trial_row(t, why.get(t.id), gone.get(p.id)) for t in trials]
        blocks = []
        for b in p.blocks:
            done = sum(
                1 for t in trials if t.block_index == b.block_index and t.status == "completed"
            )
            planned = b.n_practice + b.n_trials
            tlx = (
                "stored"
                if (b.task, b.condition) in answered
                else ("missing" if done >= planned else "-")
            )
            blocks.append(BlockRow(b.block_index, b.task, b.condition, planned, done, tlx))
        return ParticipantRecord(
            code=p.code,
            group=p.group,
            site=p.site,
            condition_order=list(p.condition_order),
            withdrawn=p.withdrawal_reason if p.withdrawn_at is not None else None,
            note=p.note,
            blocks=blocks,
            trials=rows,
            notes=notes,
            probes=probes,
            probes_due=[n for n in design.probes if n not in probes],
        )
