"""Trials left `running` by a session that is gone, as the readers show them.

A `kill -9`, a power cut or a lost lab machine ends a session without a word: its trial
stays `running` in the database, with its samples to the last committed second, until
the participant's next `study run` takes the lease over and marks it interrupted, with
its audit entry (`study.protocol.lease`, `session.recover_interrupted`). Until then the
readers (`study trial list`, `study schedule`, the terminal app's participant page) show
such a trial as `interrupted`, not `running`, and write nothing: a read command never
takes a shared database's write lock, and the marking stays the next session's.

`gone_sessions` tells from the lease table which participants' `running` trials belong
to no live session: the participant has no lease (its session ended without marking the
trial: an error past which it could not write), or the holder counts as dead by
`holder_is_dead` (its process gone from this host, or its heartbeat older than the lease
timeout). The lease is read before and after the trials, and a participant counts only
if both reads agree, so a session that starts or ends while a reader looks is never
taken for a dead one.
"""

from __future__ import annotations

import socket
from collections.abc import Collection

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.base import utcnow
from db.models.lease import SessionLease
from db.models.trial import Trial
from study.protocol.lease import LEASE_TIMEOUT_S, holder_is_dead

NEXT_RUN = "the participant's next `study run` records it and repeats the trial"


def gone_sessions(session: Session, participant_ids: Collection[int]) -> dict[int, str]:
    """The participants of `participant_ids` whose `running` trials belong to no live
    session, each with why (for the trial's `why`)."""
    if not participant_ids:
        return {}
    before = _dead_holders(session, participant_ids)
    running = set(
        session.scalars(
            select(Trial.participant_id)
            .where(Trial.participant_id.in_(list(before)), Trial.status == "running")
            .distinct()
        )
    )
    after = _dead_holders(session, running)
    return {
        pid: f"{why}; {NEXT_RUN}"
        for pid, (token, why) in after.items()
        if pid in before and before[pid][0] == token
    }


def _dead_holders(session: Session, participant_ids: Collection[int]) -> dict[int, tuple[str, str]]:
    """Participant -> (the lease's token or "", why its session is gone), for those of
    `participant_ids` with no lease or a dead holder."""
    ids = list(participant_ids)
    leases = {
        lease.participant_id: lease
        for lease in session.scalars(
            select(SessionLease)
            .where(SessionLease.participant_id.in_(ids))
            .execution_options(populate_existing=True)
        )
    }
    now, host = utcnow(), socket.gethostname()
    out: dict[int, tuple[str, str]] = {}
    for pid in ids:
        lease = leases.get(pid)
        if lease is None:
            out[pid] = ("", "its session ended without finishing it")
            continue
        why = holder_is_dead(lease, now, LEASE_TIMEOUT_S, host)
        if why is not None:
            out[pid] = (lease.token, f"its session is gone: {why}")
    return out
