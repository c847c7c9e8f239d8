"""NASA-TLX: ratings, the 15 pairwise comparisons, raw and weighted scores, storage.

Hart & Staveland (1988): six subscales rated 0-100 in steps of 5; the raw TLX is their
mean; each of the 15 pairs of subscales is presented once and the participant picks
the one that contributed more to the workload; a subscale's weight is how often it was
picked (0-5, summing to 15); the weighted TLX is sum(weight x rating) / 15.

The pairs are presented in an order (and left/right placement) drawn per participant
from the study's seed, so it is random across participants and reproducible.
A stored questionnaire can be edited, with a reason; every changed value (the pairwise
choices too) is written to the audit log with the old and new values, the reason and
the actor (`study.protocol.actor`).
"""

from __future__ import annotations

import itertools
import json
import math
import zlib
from collections.abc import Mapping, Sequence
from typing import Any, TypeGuard

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from db.base import utcnow
from db.models.audit import AuditEntry
from db.models.study import Participant
from db.models.tlx import TLX_SUBSCALES, TlxResponse
from db.models.trial import Trial
from study.errors import ReasonNeeded, StudyInputError, quoted
from study.protocol.actor import current_actor
from study.protocol.free_text import check_free_text
from study.protocol.observer import SessionObserver
from study.protocol.roster import find_participant, load_study
from study.protocol.study_rows import raw_tlx, weighted_tlx

PAIRS = tuple(itertools.combinations(TLX_SUBSCALES, 2))
"""The 15 pairs of subscales."""


def _whole_number(value: object, top: int) -> TypeGuard[int | float]:
    """Whether `value` is a finite whole number from 0 to `top` (a bool is not one)."""
    return (
        not isinstance(value, bool)
        and isinstance(value, int | float)
        and math.isfinite(value)
        and value == int(value)
        and 0 <= value <= top
    )


def check_rating(subscale: str, value: object) -> int:
    """A rating on the TLX scale.

    Parameters
    ----------
    subscale : str
        The subscale's name, for the message (e.g. ``"mental"``).
    value : object
        The rating as given (a number, from a form or a file).

    Returns
    -------
    int
        The rating, a whole number from 0 to 100 in steps of 5.

    Raises
    ------
    StudyInputError
        The value is not on the scale; the message names the subscale and the value.
    """
    if not _whole_number(value, 100) or int(value) % 5:
        raise StudyInputError(
            f"{subscale} rating {quoted(value)} is off the scale; expected 0-100 in steps of 5"
        )
    return int(value)


def check_ratings(ratings: Mapping[str, object]) -> dict[str, int]:
    """The six ratings of one questionnaire, each checked by `check_rating`.

    Parameters
    ----------
    ratings : Mapping of str to object
        Subscale -> rating, all six subscales of `TLX_SUBSCALES`.

    Returns
    -------
    dict of str to int
        The ratings in the subscales' order.

    Raises
    ------
    StudyInputError
        A subscale is missing or a rating is off the scale.
    """
    missing = [s for s in TLX_SUBSCALES if s not in ratings]
    if missing:
        raise StudyInputError(f"TLX ratings lack {', '.join(missing)}; expected all six subscales")
    return {s: check_rating(s, ratings[s]) for s in TLX_SUBSCALES}


def check_weights(weights: Mapping[str, object]) -> dict[str, int]:
    """The weights of the weighted TLX: the tallies of the 15 pairwise choices.

    Parameters
    ----------
    weights : Mapping of str to object
        Subscale -> how often it was chosen.

    Returns
    -------
    dict of str to int
        The tallies, whole numbers 0-5 that sum to 15.

    Raises
    ------
    StudyInputError
        A tally is missing, not a whole number 0-5, or the tallies do not sum to 15.
    """
    out = {}
    for s in TLX_SUBSCALES:
        w = weights.get(s)
        if not _whole_number(w, 5):
            raise StudyInputError(f"{s} weight {w!r}; expected a whole number of choices 0-5")
        out[s] = int(w)
    if sum(out.values()) != 15:
        raise StudyInputError(
            f"TLX weights sum to {sum(out.values())}; expected 15 (one per pairwise comparison)"
        )
    return out


def pair_order(study_seed: int, code: str) -> list[tuple[str, str]]:
    """The 15 pairs of subscales as this participant sees them.

    Parameters
    ----------
    study_seed : int
        The study's seed (`StudyDesign.seed`).
    code : str
        The participant's code.

    Returns
    -------
    list of (str, str)
        The pairs in the participant's own order, each with its own left/right sides:
        the same on every run for the same study and participant.
    """
    import numpy as np  # here: `study tui` reads the answered blocks before numpy loads

    rng = np.random.default_rng([study_seed, zlib.crc32(code.encode()), 0x71C])
    pairs = [PAIRS[i] for i in rng.permutation(len(PAIRS))]
    return [
        (b, a) if flip else (a, b) for (a, b), flip in zip(pairs, rng.random(15) < 0.5, strict=True)
    ]


def weights_from_choices(pairs: Sequence[tuple[str, str]], chosen: Sequence[str]) -> dict[str, int]:
    """Tally the subscale chosen from each pair.

    Parameters
    ----------
    pairs : Sequence of (str, str)
        The pairs in the order they were shown (`pair_order`).
    chosen : Sequence of str
        The subscale chosen from each pair, in the same order.

    Returns
    -------
    dict of str to int
        Subscale -> times chosen (0-5; they sum to the number of pairs).

    Raises
    ------
    StudyInputError
        There is not one choice per pair, or a choice is neither side of its pair.
    """
    if len(chosen) != len(pairs):
        raise StudyInputError(
            f"{len(chosen)} pairwise choices; expected {len(pairs)}, one per pair shown"
        )
    weights = dict.fromkeys(TLX_SUBSCALES, 0)
    for k, ((left, right), pick) in enumerate(zip(pairs, chosen, strict=True)):
        if pick not in (left, right):
            raise StudyInputError(
                f"choice {k + 1} is {pick!r}; expected {left!r} or {right!r} (pair {k + 1})"
            )
        weights[pick] += 1
    return weights


def response_scores(response: TlxResponse) -> tuple[dict[str, int], float, float | None]:
    """A stored questionnaire's scores: the one scorer `study tlx` and the analysis share.

    Parameters
    ----------
    response : TlxResponse
        A stored questionnaire.

    Returns
    -------
    tuple of (dict of str to int, float, float or None)
        The six ratings, the raw TLX and the weighted TLX (None for a questionnaire
        without the pairwise comparisons).
    """
    ratings = {s: getattr(response, s) for s in TLX_SUBSCALES}
    weights = {s: getattr(response, f"w_{s}") for s in TLX_SUBSCALES}
    weighted = weighted_tlx(ratings, weights) if weights["mental"] is not None else None
    return ratings, raw_tlx(ratings), weighted


def scored_tlx(engine: Engine, code: str | None = None) -> list[dict[str, Any]]:
    """Every stored questionnaire (or one participant's), in the order they were stored.

    Parameters
    ----------
    engine : Engine
        The study database.
    code : str or None, optional
        A participant's code; None for everyone.

    Returns
    -------
    list of dict
        One row per questionnaire: participant, group, task, condition, the six ratings,
        tlx_raw and tlx_weighted (None without the pairwise comparisons).

    Raises
    ------
    StudyInputError
        `code` names no participant of the study.
    """
    query = select(TlxResponse, Participant.code, Participant.group).join(Participant)
    if code:
        query = query.where(Participant.code == code)
    rows = []
    with Session(engine) as session:
        if code:  # an unknown code is a mistake, not a participant without questionnaires
            find_participant(session, load_study(session)[0], code)
        for response, pcode, group in session.execute(query.order_by(TlxResponse.id)):
            ratings, raw, weighted = response_scores(response)
            rows.append(
                {
                    "participant": pcode,
                    "group": group,
                    "task": response.task,
                    "condition": response.condition,
                    **ratings,
                    "tlx_raw": raw,
                    "tlx_weighted": weighted,
                }
            )
    return rows


def store_tlx(
    engine: Engine,
    code: str,
    task: str,
    condition: str,
    ratings: Mapping[str, object],
    chosen: Sequence[str] | None = None,
    reason: str | None = None,
    actor: str | None = None,
    observer: SessionObserver | None = None,
) -> tuple[TlxResponse, bool]:
    """Store (or edit) the questionnaire of one block; return it and whether it was new.

    An edit needs a `reason`, and so does a questionnaire for a block with no completed
    trial yet (the lab confirms why; the reason goes to the audit log);
    `actor` defaults to `current_actor()`. Once it is committed, `observer` is told (a
    `questionnaire` event: the participant's keys, the block's task and condition,
    whether it was new, the raw and weighted TLX).

    Parameters
    ----------
    engine : Engine
        The study database.
    code, task, condition : str
        The block: the participant's code, its task and its condition.
    ratings : Mapping of str to object
        Subscale -> rating (0-100 in steps of 5), all six.
    chosen : Sequence of str or None, optional
        The subscale chosen from each pair of `pair_order`, in that order; None for a
        questionnaire without the pairwise comparisons (raw TLX only).
    reason : str or None, optional
        Why the questionnaire is edited (or entered before the block's first trial).
    actor : str or None, optional
        Who enters it (default `current_actor()`).
    observer : SessionObserver or None, optional
        Told the `questionnaire` event once it is committed.

    Returns
    -------
    tuple of (TlxResponse, bool)
        The stored questionnaire and whether it was new (False for an edit).

    Raises
    ------
    StudyInputError
        A rating or choice is off the scale, the participant or block is unknown, or a
        reason is needed and missing; nothing is stored then.
    """
    response, new = _store_tlx(engine, code, task, condition, ratings, chosen, reason, actor)
    if observer is not None:
        with Session(engine) as session:
            study, _ = load_study(session)
            group = find_participant(session, study, code).group
        _, raw, weighted = response_scores(response)
        observer.event(
            "questionnaire",
            study=study.name,
            participant=code,
            group=group,
            task=task,
            condition=condition,
            new=new,
            raw_tlx=raw,
            weighted_tlx=weighted,
        )
    return response, new


def _store_tlx(
    engine: Engine,
    code: str,
    task: str,
    condition: str,
    ratings: Mapping[str, object],
    chosen: Sequence[str] | None,
    reason: str | None,
    actor: str | None,
) -> tuple[TlxResponse, bool]:
    ratings = check_ratings(ratings)
    who = current_actor(actor)
    reason = check_free_text("reason", reason) if reason is not None else None
    with Session(engine) as session, session.begin():
        study, _ = load_study(session)
        participant = find_participant(session, study, code)
        blocks = {(b.task, b.condition) for b in participant.blocks}
        if (task, condition) not in blocks:
            raise StudyInputError(
                f"{code} has no {task}/{condition} block; expected one of "
                f"{', '.join(f'{t}/{c}' for t, c in sorted(blocks))}"
            )
        weights: Mapping[str, int | None] = dict.fromkeys(TLX_SUBSCALES)
        pairwise = None
        if chosen is not None:
            pairs = pair_order(study.seed, code)
            weights = weights_from_choices(pairs, chosen)
            pairwise = [[a, b, c] for (a, b), c in zip(pairs, chosen, strict=True)]
        existing = session.scalars(
            select(TlxResponse).where(
                TlxResponse.participant_id == participant.id,
                TlxResponse.task == task,
                TlxResponse.condition == condition,
            )
        ).first()
        values: dict[str, Any] = {**ratings, **{f"w_{s}": weights[s] for s in TLX_SUBSCALES}}
        if existing is None and participant.withdrawn_at is not None:
            raise StudyInputError(
                f"participant {code} withdrew on {participant.withdrawn_at:%Y-%m-%d}; expected "
                "an enrolled participant for a new questionnaire (`study participant "
                "reinstate` first if the withdrawal was a mistake)"
            )
        if existing is None:
            ran = session.scalar(
                select(func.count())
                .select_from(Trial)
                .where(
                    Trial.participant_id == participant.id,
                    Trial.task == task,
                    Trial.condition == condition,
                    Trial.status == "completed",
                )
            )
            if not ran and not reason:
                raise ReasonNeeded(
                    f"{code} {task}/{condition} has no completed trial yet; a questionnaire "
                    "for a block that has not run needs a reason, kept in the audit log"
                )
            response = TlxResponse(
                participant_id=participant.id,
                task=task,
                condition=condition,
                pairwise=pairwise,
                **values,
            )
            session.add(response)
            session.flush()
            session.add(
                AuditEntry(
                    entity="tlx_response",
                    entity_id=response.id,
                    field="entered",
                    old_value=None,
                    new_value=_audit_text(
                        {
                            "participant": code,
                            "task": task,
                            "condition": condition,
                            **values,
                            "pairwise": pairwise,
                        }
                    ),
                    reason=reason,
                    actor=who,
                )
            )
            if not ran:  # stored before its block ran: why, and by whom
                session.add(
                    AuditEntry(
                        entity="tlx_response",
                        entity_id=response.id,
                        field="stored_before_block_ran",
                        old_value=None,
                        new_value="0 completed trials",
                        reason=reason,
                        actor=who,
                    )
                )
                session.flush()
            session.expunge(response)
            return response, True
        if not reason:
            raise ReasonNeeded(
                f"{code} {task}/{condition} already has a questionnaire; an edit needs a "
                "reason, kept in the audit log"
            )
        if chosen is None:  # keep the stored comparisons when only ratings are edited
            values.update({f"w_{s}": getattr(existing, f"w_{s}") for s in TLX_SUBSCALES})
            pairwise = existing.pairwise
        values["pairwise"] = pairwise
        for name, new in values.items():
            old = getattr(existing, name)
            if old != new:
                session.add(
                    AuditEntry(
                        entity="tlx_response",
                        entity_id=existing.id,
                        field=name,
                        old_value=_audit_text(old),
                        new_value=_audit_text(new),
                        reason=reason,
                        actor=who,
                    )
                )
                setattr(existing, name, new)
        existing.updated_at = utcnow()
        session.flush()
        session.expunge(existing)
        return existing, False


def _audit_text(value: object) -> str | None:
    """A stored value as audit text (the pairwise choices as JSON)."""
    if value is None:
        return None
    return json.dumps(value) if isinstance(value, list | dict) else str(value)


def load_tlx(engine: Engine, code: str, task: str, condition: str) -> TlxResponse | None:
    """The stored questionnaire of one block, for editing it.

    Parameters
    ----------
    engine : Engine
        The study database.
    code, task, condition : str
        The block: the participant's code, its task and its condition.

    Returns
    -------
    TlxResponse or None
        The questionnaire (detached from its session), None if there is none.
    """
    with Session(engine) as session:
        response = session.scalars(
            select(TlxResponse)
            .join(Participant)
            .where(
                Participant.code == code,
                TlxResponse.task == task,
                TlxResponse.condition == condition,
            )
        ).first()
        if response is not None:
            session.expunge(response)
    return response


def answered_blocks(engine: Engine) -> set[tuple[str, str, str]]:
    """The blocks that have their questionnaire.

    Parameters
    ----------
    engine : Engine
        The study database.

    Returns
    -------
    set of (str, str, str)
        (participant code, task, condition) of each such block.
    """
    with Session(engine) as session:
        rows = session.execute(
            select(Participant.code, TlxResponse.task, TlxResponse.condition).join(Participant)
        ).all()
    return {tuple(r) for r in rows}  # type: ignore[misc]


def tlx_audit(engine: Engine, response_id: int) -> list[AuditEntry]:
    """The audit trail of one questionnaire.

    Parameters
    ----------
    engine : Engine
        The study database.
    response_id : int
        The questionnaire's id (`TlxResponse.id`).

    Returns
    -------
    list of AuditEntry
        Its audit rows, oldest first, detached from their session.
    """
    with Session(engine) as session:
        entries = session.scalars(
            select(AuditEntry)
            .where(AuditEntry.entity == "tlx_response", AuditEntry.entity_id == response_id)
            .order_by(AuditEntry.id)
        ).all()
        session.expunge_all()
    return list(entries)
