"""One running session per participant: leases with a heartbeat.

`hold_lease` takes the participant's row in `session_leases` inside a
`write_transaction` (SQLite `BEGIN IMMEDIATE`, a PostgreSQL advisory lock), so two
processes or two lab machines asking at once see each other. While the session runs a
daemon thread renews the row's heartbeat every `HEARTBEAT_S`; the session releases the
row when it ends, however it ends short of a crash.

A second session is refused while the holder is alive. The holder counts as dead when
its process is gone from this host (checked with signal 0, which makes a `kill -9`'d
session recoverable at once) or when its heartbeat is older than `LEASE_TIMEOUT_S`
(another machine, a powered-off PC); the newcomer then takes the lease over and the
dead session's `running` trial is recovered as interrupted, as before leases.

Heartbeats carry the holder's clock; lab machines keep NTP time to well under a second,
against a 30 s timeout. A holder that finds its row gone or taken (it was stalled past
the timeout) sets `lost`; the runner stops at its next step, and its trial's final
update only applies while the trial is still `running`.

SQLAlchemy and the databases offer no cross-backend lease: PostgreSQL session advisory
locks die with the connection but need one connection held per session, which SQLite
has no equivalent of, so the row is written by hand.
"""

from __future__ import annotations

import os
import secrets
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy import Engine, delete, update
from sqlalchemy.exc import DBAPIError
from sqlalchemy.orm import Session

from db.base import utcnow
from db.engine import write_transaction
from db.models.lease import SessionLease
from study.errors import StudyInputError

LEASE_TIMEOUT_S = 30.0
"""A heartbeat older than this marks the holder dead (another machine, a frozen PC)."""
HEARTBEAT_S = 2.0
"""How often the holder renews its heartbeat."""


class SessionBusyError(StudyInputError):
    """The participant has a live session elsewhere."""


class LeaseLostError(StudyInputError):
    """This session's lease was taken over (it was stalled past the timeout)."""


def _aware(value: datetime) -> datetime:
    """SQLite returns naive datetimes; they are stored as UTC."""
    return value if value.tzinfo is not None else value.replace(tzinfo=UTC)


def process_alive(pid: int) -> bool:
    """True if process `pid` runs on this host (signal 0 checks without signalling).

    A zombie (dead, not yet reaped: an orphan under an init that does not reap) is dead.
    """
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by another user
        pass
    except OSError:
        return False
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:  # no /proc (macOS, Windows): signal 0 is all there is
        return True
    return stat.rpartition(")")[2].split()[0] not in ("Z", "X")


def holder_is_dead(lease: SessionLease, now: datetime, timeout_s: float, host: str) -> str | None:
    """Why the holder of `lease` counts as dead, or None while it is alive."""
    age_s = (now - _aware(lease.heartbeat_at)).total_seconds()
    if lease.host == host and not process_alive(lease.pid):
        return f"its process {lease.pid} on {lease.host} is gone"
    if age_s > timeout_s:
        return f"no heartbeat from {lease.host} process {lease.pid} for {age_s:.0f} s"
    return None


@dataclass
class LeaseHandle:
    """A held lease: `lost` is set when another session took it over."""

    engine: Engine
    participant_id: int
    code: str
    token: str
    taken_over: str | None
    """Why a dead holder's lease was replaced (None when the lease was free)."""
    lost: threading.Event = field(default_factory=threading.Event)
    _stop: threading.Event = field(default_factory=threading.Event)

    def check(self) -> None:
        """Raise `LeaseLostError` if another session has taken the lease over."""
        if self.lost.is_set():
            raise LeaseLostError(
                f"the session lease of {self.code} was taken over by another session "
                "(this one was stalled past the lease timeout); stopped, its trial stays "
                "with the other session's recovery"
            )

    def beat(self, now: datetime | None = None) -> bool:
        """Renew the heartbeat; False (and `lost` set) if the lease is no longer ours."""
        with self.engine.begin() as conn:
            result = conn.execute(
                update(SessionLease)
                .where(
                    SessionLease.participant_id == self.participant_id,
                    SessionLease.token == self.token,
                )
                .values(heartbeat_at=now or utcnow())
            )
        if result.rowcount == 0:
            self.lost.set()
            return False
        return True

    def _heartbeat(self, interval_s: float) -> None:
        while not self._stop.wait(interval_s):
            try:
                if not self.beat():
                    return
            except DBAPIError:  # the server away for a moment: try again next beat
                continue

    def release(self) -> None:
        self._stop.set()
        with self.engine.begin() as conn:
            conn.execute(
                delete(SessionLease).where(
                    SessionLease.participant_id == self.participant_id,
                    SessionLease.token == self.token,
                )
            )


def acquire_lease(
    engine: Engine,
    participant_id: int,
    code: str,
    actor: str | None = None,
    *,
    timeout_s: float = LEASE_TIMEOUT_S,
) -> LeaseHandle:
    """Take the participant's lease, or refuse with one line naming the live holder."""
    host, now = socket.gethostname(), utcnow()
    token = secrets.token_hex(16)
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        lease = session.get(SessionLease, participant_id)
        why = None
        if lease is not None:
            why = holder_is_dead(lease, now, timeout_s, host)
            if why is None:
                age_s = (now - _aware(lease.heartbeat_at)).total_seconds()
                when = (
                    "its process is alive on this host; once it ends, a new session takes "
                    "over at once"
                    if lease.host == host
                    else f"once its heartbeat is {timeout_s:.0f} s old, a new session takes over"
                )
                raise SessionBusyError(
                    f"participant {code} already has a session running on {lease.host} "
                    f"(process {lease.pid}, by {lease.actor or 'unknown'}, heartbeat "
                    f"{age_s:.0f} s ago); expected one session per participant: wait for "
                    f"it to end ({when})"
                )
            session.delete(lease)
            session.flush()
        session.add(
            SessionLease(
                participant_id=participant_id,
                token=token,
                host=host[:255],
                pid=os.getpid(),
                actor=actor,
                acquired_at=now,
                heartbeat_at=now,
            )
        )
        session.commit()
    return LeaseHandle(engine, participant_id, code, token, why)


@contextmanager
def hold_lease(
    engine: Engine,
    participant_id: int,
    code: str,
    actor: str | None = None,
    *,
    heartbeat_s: float = HEARTBEAT_S,
) -> Iterator[LeaseHandle]:
    """Hold the participant's lease for the block, renewed by a heartbeat thread."""
    handle = acquire_lease(engine, participant_id, code, actor)
    thread = threading.Thread(
        target=handle._heartbeat, args=(heartbeat_s,), name=f"lease-{code}", daemon=True
    )
    thread.start()
    failed = False
    try:
        yield handle
    except BaseException:
        failed = True
        raise
    finally:
        handle._stop.set()
        thread.join(timeout=heartbeat_s + 5)
        try:
            handle.release()
        except Exception:
            # after the session's own error (a full disk, a lost server) releasing can fail
            # the same way: that error is the one to report; the row left behind names a
            # process that has ended, so the next session takes it over at once
            if not failed:
                raise
