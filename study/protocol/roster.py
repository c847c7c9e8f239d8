"""The study in the database: creating it, enrolling participants, their schedules.

Service functions own the queries (the CLI and the TUI call these, never SQL).
Enrolment reads the group's orders and the highest code and writes the new participant
inside one `write_transaction` (SQLite `BEGIN IMMEDIATE`, a PostgreSQL advisory lock),
so two lab machines enrolling at once still get distinct codes and balanced orders.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session, selectinload

from db.engine import write_transaction
from db.models.audit import AuditEntry
from db.models.study import CODE_PATTERN, Participant, ScheduleBlock, Study
from db.models.trial import Trial
from study.errors import StudyInputError
from study.protocol.actor import current_actor
from study.protocol.design import StudyDesign, next_order
from study.protocol.orphans import gone_sessions

CODE_DIGITS = 3
MAX_SITE_CHARS = 64
MAX_ENROL = 1000
"""The most participants one `study participant add` enrols (a design's largest group)."""
"""`participants.site` holds 64 characters (PostgreSQL refuses more; SQLite would not)."""


def create_study(engine: Engine, design: StudyDesign, design_toml: str) -> Study:
    """Store the study; a database holds one study."""
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        existing = session.scalars(select(Study)).first()
        if existing is not None:
            raise StudyInputError(
                f"the database already holds the study {existing.name!r}; expected an empty "
                "database (one study per database)"
            )
        study = Study(
            name=design.name, design_toml=design_toml, design=design.to_dict(), seed=design.seed
        )
        session.add(study)
        session.flush()
        session.expunge(study)
        session.commit()
    return study


def find_study(session: Session) -> Study:
    """The database's study row (its design as stored, not read: `load_study`)."""
    study = session.scalars(select(Study)).first()
    if study is None:
        raise StudyInputError("the database holds no study; run `study init --design FILE` first")
    return study


def load_study(session: Session) -> tuple[Study, StudyDesign]:
    study = find_study(session)
    return study, StudyDesign.from_dict(study.design)


def read_design(engine: Engine) -> StudyDesign:
    """The study's design, read once for what a session does around its trials (its
    probes, its streams) and handed on (`SessionSettings.design`)."""
    with Session(engine) as session:
        return load_study(session)[1]


def find_participant(session: Session, study: Study, code: str) -> Participant:
    """The participant `code` of `study`; a one-line error naming it when there is none."""
    participant = session.scalars(
        select(Participant).where(Participant.study_id == study.id, Participant.code == code)
    ).first()
    if participant is None:
        raise StudyInputError(
            f"unknown participant {code!r}; expected a code from `study schedule`"
        )
    return participant


def plan_blocks(design: StudyDesign, order: tuple[str, ...]) -> list[dict[str, Any]]:
    """A participant's blocks: each task, its conditions in the participant's order."""
    blocks: list[dict[str, Any]] = []
    for task in design.tasks:
        for condition in order:
            blocks.append(
                {
                    "block_index": len(blocks),
                    "task": task,
                    "condition": condition,
                    "n_practice": design.practice_trials,
                    "n_trials": design.trials_per_condition,
                    "break_after_s": design.break_s,
                }
            )
    return blocks


def next_code(session: Session, study: Study, prefix: str) -> str:
    """The code after the highest `PREFIX<digits>` code of the study.

    Not the participant count plus one: with imported participants (any code) that
    collides with a code already taken (P001-P002 enrolled and P004 imported would make
    the next enrolment choose P004, and every later one fail). Gaps are not reused, so
    codes keep the order of enrolment.
    """
    codes = session.scalars(
        select(Participant.code).where(
            Participant.study_id == study.id, Participant.code.like(f"{prefix}%")
        )
    ).all()
    digits = [c[len(prefix) :] for c in codes]
    numbers = [int(d) for d in digits if d.isascii() and d.isdecimal()]
    code = f"{prefix}{max(numbers, default=0) + 1:0{CODE_DIGITS}d}"
    if not CODE_PATTERN.match(code):
        raise StudyInputError(
            f"next participant code {code!r} has more than 6 digits; expected codes "
            f"{prefix}001 to {prefix}999999"
        )
    return code


def add_participant(
    engine: Engine, group: str, site: str | None = None, actor: str | None = None
) -> Participant:
    """Enrol the next participant of `group`: next code, balancing order, schedule."""
    return enrol(engine, group, site, 1, beyond_target=True, actor=actor)[0]


def enrol(
    engine: Engine,
    group: str,
    site: str | None = None,
    count: int = 1,
    *,
    beyond_target: bool = False,
    actor: str | None = None,
) -> list[Participant]:
    """Enrol the next `count` participants of `group` in one transaction (all or none),
    each with an audit row (group, site, condition order, who). Refused when it would take
    the group past its target in the design, unless `beyond_target` (a replacement)."""

    who = current_actor(actor)
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        study, design = load_study(session)
        if group not in design.groups:
            raise StudyInputError(
                f"unknown group {group!r}; expected one of {', '.join(design.groups)}"
            )
        if site is not None and not (0 < len(site) <= MAX_SITE_CHARS and site.isprintable()):
            raise StudyInputError(
                f"site {site!r}; expected 1-{MAX_SITE_CHARS} printable characters"
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
        room = max(target - len(used), 0)
        if count > room and not beyond_target:
            raise StudyInputError(
                f"--count {count} for group {group}, which has {len(used)} of its {target} "
                f"enrolled; expected at most {room} (--beyond-target enrols replacements "
                "past the design's target)"
            )
        if count > MAX_ENROL:
            raise StudyInputError(f"--count {count}; expected at most {MAX_ENROL} at once")
        added = []
        for _ in range(count):
            order = next_order(design, group, used)
            used.append(order)
            code = next_code(session, study, design.code_prefix)
            participant = Participant(
                study_id=study.id, code=code, group=group, condition_order=list(order), site=site
            )
            participant.blocks = [ScheduleBlock(**b) for b in plan_blocks(design, order)]
            session.add(participant)
            session.flush()
            session.add(
                AuditEntry(
                    entity="participant",
                    entity_id=participant.id,
                    field="enrolled",
                    old_value=None,
                    actor=who,
                    new_value=json.dumps(
                        {"code": code, "group": group, "site": site, "condition_order": list(order)}
                    ),
                    reason="past the group's target" if len(used) > target else None,
                )
            )
            session.flush()
            added.append(participant)
        session.expunge_all()
        session.commit()
    return added


@dataclass(frozen=True)
class BlockProgress:
    block_index: int
    task: str
    condition: str
    planned: int
    """Practice plus measured trials."""
    completed: int
    interrupted: int


def schedule(engine: Engine, design: StudyDesign | None = None) -> dict[str, Any]:
    """The plan and progress of every participant, and each group's fill (`design`: the
    study's design as the caller already read it from the same database, else read here).

    Three queries whatever the study's size (the study, its participants with their
    blocks, the trial counts): per-participant queries made 76 round trips for 36
    participants, which a multi-site PostgreSQL server pays in network latency and the
    terminal app's overview in start-up time.
    """
    with Session(engine) as session:
        if design is None:
            study, design = load_study(session)
        else:
            study = find_study(session)
        participants = session.scalars(
            select(Participant)
            .where(Participant.study_id == study.id)
            .order_by(Participant.id)
            .options(selectinload(Participant.blocks))
        ).all()
        counts = session.execute(
            select(Trial.participant_id, Trial.block_index, Trial.status, func.count())
            .join(Participant, Trial.participant_id == Participant.id)
            .where(Participant.study_id == study.id)
            .group_by(Trial.participant_id, Trial.block_index, Trial.status)
        ).all()
        # a running trial whose session is gone (kill -9) counts as interrupted
        gone = gone_sessions(session, {pid for pid, _, st, _ in counts if st == "running"})
        done: dict[tuple[int, int, str], int] = {}
        for pid, b, st, n in counts:
            key = (pid, b, "interrupted" if st == "running" and pid in gone else st)
            done[key] = done.get(key, 0) + n
        rows = []
        for p in participants:
            blocks = [
                BlockProgress(
                    b.block_index,
                    b.task,
                    b.condition,
                    b.n_practice + b.n_trials,
                    done.get((p.id, b.block_index, "completed"), 0),
                    done.get((p.id, b.block_index, "interrupted"), 0),
                ).__dict__
                for b in p.blocks
            ]
            planned = sum(b["planned"] for b in blocks)
            completed = sum(b["completed"] for b in blocks)
            rows.append(
                {
                    "code": p.code,
                    "group": p.group,
                    "site": p.site,
                    "condition_order": list(p.condition_order),
                    "trials_planned": planned,
                    "trials_completed": completed,
                    "blocks": blocks,
                    "withdrawn": p.withdrawal_reason if p.withdrawn_at is not None else None,
                    "note": p.note,
                }
            )
        fill = {
            g: {"target": n, "enrolled": sum(1 for r in rows if r["group"] == g)}
            for g, n in design.groups.items()
        }
    return {"study": study.name, "groups": fill, "participants": rows}
