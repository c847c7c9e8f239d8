"""Audited corrections: a measured trial marked invalid (and valid again), a withdrawal
undone, a wrong group corrected before the first trial.

Each correction changes the stored value and adds an audit row (`db.models.audit`) with
the old and the new value, the reason and who made it, in one transaction; nothing is
deleted. An invalid trial keeps its row, samples and measures (every export has them);
the analysis leaves it out and lists it with its reason among the exclusions
(`study.analysis.frames.without_excluded`). The command line (`study trial`,
`study participant`) and the terminal app's participant page call these functions.
"""

from __future__ import annotations

import json

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from db.engine import write_transaction
from db.models.audit import AuditEntry
from db.models.probe import ProbeTrial
from db.models.study import Participant, ScheduleBlock
from db.models.trial import Trial
from study.errors import StudyInputError
from study.protocol.actor import current_actor
from study.protocol.design import next_order
from study.protocol.roster import find_participant, load_study, plan_blocks
from study.protocol.withdrawal import _check_text

__all__ = [
    "correct_group",
    "describe_trial",
    "invalid_trials",
    "mark_trial",
    "reinstate",
]


def describe_trial(trial: Trial, code: str) -> str:
    """`P001 lcca/VO trial 2 (attempt 1)`: a trial as the experimenter knows it."""
    kind = "practice" if trial.practice else "trial"
    return (
        f"{code} {trial.task}/{trial.condition} {kind} {trial.trial_index + 1} "
        f"(attempt {trial.attempt})"
    )


def mark_trial(
    engine: Engine, trial_id: int, valid: bool, reason: str, actor: str | None = None
) -> str:
    """Mark trial `trial_id` invalid (`valid` False) or valid again, with `reason`;
    audited. Only a completed measured trial can be marked; marking a trial as what it
    already is is refused. Returns the trial's description."""
    reason = _check_text("reason", reason)
    who = current_actor(actor)
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        load_study(session)
        trial = session.get(Trial, trial_id)
        if trial is None:
            raise StudyInputError(
                f"unknown trial id {trial_id}; expected an id from "
                "`study trial list --participant CODE`"
            )
        code = session.get_one(Participant, trial.participant_id).code
        what = describe_trial(trial, code)
        if trial.practice or trial.status != "completed":
            state = "a practice trial" if trial.practice else f"{trial.status}"
            raise StudyInputError(
                f"trial {trial_id} ({what}) is {state}; expected a completed measured trial"
            )
        if valid and trial.invalid_reason is None:
            raise StudyInputError(f"trial {trial_id} ({what}) is valid; expected an invalid trial")
        if not valid and trial.invalid_reason is not None:
            raise StudyInputError(
                f"trial {trial_id} ({what}) is already marked invalid "
                f"({trial.invalid_reason}); expected a valid trial"
            )
        old, new = ("invalid", "valid") if valid else ("valid", "invalid")
        session.add(
            AuditEntry(
                entity="trial",
                entity_id=trial.id,
                field="validity",
                old_value=old,
                new_value=new,
                reason=reason,
                actor=who,
            )
        )
        trial.invalid_reason = None if valid else reason
        session.commit()
    return what


def invalid_trials(engine: Engine) -> dict[tuple[str, str, str, int], str]:
    """(code, task, condition, trial number from 1) -> reason, for every completed
    measured trial marked invalid: the keys of `trial_frame`'s rows."""
    with Session(engine) as session:
        rows = session.execute(
            select(Participant.code, Trial)
            .join(Trial, Trial.participant_id == Participant.id)
            .where(Trial.invalid_reason.is_not(None), Trial.practice.is_(False))
        ).all()
    return {
        (code, t.task, t.condition, t.trial_index + 1): t.invalid_reason or "" for code, t in rows
    }


def reinstate(engine: Engine, code: str, reason: str, actor: str | None = None) -> None:
    """Undo `code`'s withdrawal (audited): they are in the study again, their sessions
    go on where they stopped and the analysis counts them."""
    reason = _check_text("reason", reason)
    who = current_actor(actor)
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        study, _ = load_study(session)
        p = find_participant(session, study, code)
        if p.withdrawn_at is None:
            raise StudyInputError(
                f"participant {code} is not withdrawn; expected a withdrawn participant"
            )
        session.add(
            AuditEntry(
                entity="participant",
                entity_id=p.id,
                field="status",
                old_value="withdrawn",
                new_value="enrolled",
                reason=reason,
                actor=who,
            )
        )
        p.withdrawn_at = None
        p.withdrawal_reason = None
        session.commit()


def correct_group(
    engine: Engine,
    code: str,
    group: str,
    reason: str,
    actor: str | None = None,
    *,
    beyond_target: bool = False,
) -> tuple[str, ...]:
    """Move `code` to `group` before their first trial (audited): they take the condition
    order the new group's counterbalancing gives its next member, and their schedule is
    planned again. Refused once a trial or a probe trial of theirs is stored, and past
    the new group's target unless `beyond_target`. Returns the new condition order."""
    reason = _check_text("reason", reason)
    who = current_actor(actor)
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        study, design = load_study(session)
        p = find_participant(session, study, code)
        if group not in design.groups:
            raise StudyInputError(
                f"unknown group {group!r}; expected one of {', '.join(design.groups)}"
            )
        if group == p.group:
            raise StudyInputError(
                f"participant {code} is in the {group} group already; expected another group"
            )
        n_trials = session.scalar(
            select(func.count()).select_from(Trial).where(Trial.participant_id == p.id)
        )
        n_probes = session.scalar(
            select(func.count()).select_from(ProbeTrial).where(ProbeTrial.participant_id == p.id)
        )
        if n_trials or n_probes:
            stored = f"{n_trials} trials" if n_trials else f"{n_probes} probe trials"
            raise StudyInputError(
                f"participant {code} has {stored} stored in the {p.group} group; expected a "
                "participant before their first trial (withdraw them and enrol anew)"
            )
        used = [
            tuple(u)
            for u in session.scalars(
                select(Participant.condition_order).where(
                    Participant.study_id == study.id, Participant.group == group
                )
            ).all()
        ]
        target = design.groups[group]
        if len(used) >= target and not beyond_target:
            raise StudyInputError(
                f"group {group} has its {target} participants; expected a group with room "
                "(--beyond-target moves past the design's target)"
            )
        order = next_order(design, group, used)
        old = {"group": p.group, "condition_order": list(p.condition_order)}
        new = {"group": group, "condition_order": list(order)}
        session.add(
            AuditEntry(
                entity="participant",
                entity_id=p.id,
                field="group",
                old_value=json.dumps(old),
                new_value=json.dumps(new),
                reason=reason,
                actor=who,
            )
        )
        for block in list(p.blocks):
            session.delete(block)
        session.flush()
        p.group = group
        p.condition_order = list(order)
        p.blocks = [ScheduleBlock(**b) for b in plan_blocks(design, order)]
        session.commit()
    return order
