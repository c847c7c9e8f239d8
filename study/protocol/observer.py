"""What a session tells the world outside its database while it runs.

The session runner hands each event of a session (its start, each trial's place in it and
its start, every batch of samples, a wait for the database, each trial's end with its
outcome, the session's end) to an observer (several: `Observers`),
so that publishing them (the Lab Streaming Layer, `study.lsl`) or recording other
instruments beside the trials plugs in without the runner knowing how. Other parts of
a session (probes, the questionnaire) report theirs through `event`.

Each trial's clock: sample time `t_s` of the trial happens at wall time
`clock_origin_s + t_s / clock_rate` on `time.monotonic()` (the runner keeps a paced or
real-time session within one step of it; an unpaced simulated session is not at real
time, `realtime` False).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from db.models.study import ScheduleBlock
    from study.protocol.tasks import Task


@dataclass(frozen=True)
class PendingTrial:
    """A trial of the participant's schedule still to run: its block, whether it is a
    practice trial, and its place in the block."""

    block: ScheduleBlock
    practice: bool
    trial_index: int


@dataclass(frozen=True)
class SessionInfo:
    study: str
    participant: str
    group: str
    driver: str
    pace: float | None
    """Times real time of a paced simulated session; None: as fast as it goes (simulated)
    or real time (a person at the hardware or keyboard)."""
    tasks: tuple[Task, ...] = ()
    """The tasks of the session's trials, in the order they first come."""


@dataclass(frozen=True)
class TrialInfo:
    trial_id: int
    task: Task
    condition: str
    block_index: int
    trial_index: int
    practice: bool
    attempt: int
    clock_origin_s: float
    """`time.monotonic()` at the trial's t = 0, s."""
    clock_rate: float
    """Trial seconds per wall second (the pace; 1 at real time)."""
    realtime: bool
    """The trial's clock keeps step with the wall clock (paced, or a real-time driver)."""

    def marker_fields(self) -> dict[str, Any]:
        return {
            "trial_id": self.trial_id,
            "task": self.task.name,
            "condition": self.condition,
            "block": self.block_index,
            "trial": self.trial_index,
            "practice": self.practice,
            "attempt": self.attempt,
            "clock_rate": self.clock_rate,
        }


class SessionObserver:
    """Receives a session's events; every method does nothing unless overridden."""

    def session_started(self, session: SessionInfo) -> None:
        """Before the first trial (the participant's lease is held)."""

    def trial_progress(self, pending: PendingTrial, k: int, n: int) -> None:
        """Before each trial, its driver opened or its row written: `pending` is the
        `k`-th (from 0) of the `n` trials this session runs."""

    def trial_started(self, trial: TrialInfo) -> None:
        """The trial's row is `running`, its loop started, its clock at 0."""

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        """After each step of the loop: the rows acquired (the task's `sample_columns`,
        possibly none), already handed to the sample writer."""

    def storage_wait(self, waited_s: float | None, held: int) -> None:
        """A watched session (`SessionSettings.wait_out_storage`) waits for a lock another
        program holds: `waited_s` so far, `held` samples kept in memory meanwhile; (None,
        0) once they are committed."""

    def trial_ended(self, trial: TrialInfo, status: str, outcome: dict[str, Any]) -> None:
        """`status`: `completed` (outcome: success and the measures), `stopped` (the
        session was stopped), or `interrupted` (an error; outcome names it)."""

    def session_ended(self) -> None:
        """After the last trial, also when the session ended on an error."""

    def event(self, kind: str, **fields: Any) -> None:
        """Something else of the participant's: `probe` (a probe trial), `questionnaire`
        (NASA-TLX stored), with their own fields; these carry `study`, `participant` and
        `group` themselves (a probe or a questionnaire may come outside a session)."""


class Observers(SessionObserver):
    """Several observers, each told every event in order."""

    def __init__(self, observers: Sequence[SessionObserver]) -> None:
        self.observers = tuple(observers)

    def session_started(self, session: SessionInfo) -> None:
        for o in self.observers:
            o.session_started(session)

    def trial_progress(self, pending: PendingTrial, k: int, n: int) -> None:
        for o in self.observers:
            o.trial_progress(pending, k, n)

    def trial_started(self, trial: TrialInfo) -> None:
        for o in self.observers:
            o.trial_started(trial)

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        for o in self.observers:
            o.samples(trial, rows)

    def storage_wait(self, waited_s: float | None, held: int) -> None:
        for o in self.observers:
            o.storage_wait(waited_s, held)

    def trial_ended(self, trial: TrialInfo, status: str, outcome: dict[str, Any]) -> None:
        for o in self.observers:
            o.trial_ended(trial, status, outcome)

    def session_ended(self) -> None:
        for o in self.observers:
            o.session_ended()

    def event(self, kind: str, **fields: Any) -> None:
        for o in self.observers:
            o.event(kind, **fields)


class LastingObserver(SessionObserver):
    """One observer across many sessions (a terminal app's trials, each its own
    session; a probe run): a session's start is passed on only when the participant, the
    driver or the pace changes, or trials follow a session without any (the one before
    then ended), its end only by `close()`.
    An event of a participant with no session open opens one for them (driver: the
    event's, else `keyboard`; no pace), so that it goes out with their keys."""

    def __init__(self, observer: SessionObserver) -> None:
        self.observer = observer
        self.session: SessionInfo | None = None

    @staticmethod
    def _key(s: SessionInfo) -> tuple[Any, ...]:
        return (s.study, s.participant, s.group, s.driver, s.pace, bool(s.tasks))

    def session_started(self, session: SessionInfo) -> None:
        if self.session is not None and self._key(self.session) == self._key(session):
            return
        self.close()
        try:
            self.observer.session_started(session)
        except BaseException:
            self.observer.session_ended()
            raise
        self.session = session

    def trial_progress(self, pending: PendingTrial, k: int, n: int) -> None:
        self.observer.trial_progress(pending, k, n)

    def trial_started(self, trial: TrialInfo) -> None:
        self.observer.trial_started(trial)

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        self.observer.samples(trial, rows)

    def storage_wait(self, waited_s: float | None, held: int) -> None:
        self.observer.storage_wait(waited_s, held)

    def trial_ended(self, trial: TrialInfo, status: str, outcome: dict[str, Any]) -> None:
        self.observer.trial_ended(trial, status, outcome)

    def session_ended(self) -> None:
        """Kept open for the next session (`close()` ends it)."""

    def event(self, kind: str, **fields: Any) -> None:
        s = self.session
        keys = tuple(fields.get(k) for k in ("study", "participant", "group"))
        if s is None or (s.study, s.participant, s.group) != keys:
            self.session_started(
                SessionInfo(
                    str(fields.get("study")),
                    str(fields.get("participant")),
                    str(fields.get("group")),
                    str(fields.get("driver", "keyboard")),
                    None,
                )
            )
        self.observer.event(kind, **fields)

    def close(self) -> None:
        """End the session open, if any."""
        if self.session is not None:
            self.session = None
            self.observer.session_ended()


@contextmanager
def session_ending(observer: SessionObserver) -> Iterator[None]:
    """Tell `observer` the session ended, however it ends."""
    try:
        yield
    finally:
        observer.session_ended()


@contextmanager
def trial_ending(
    observer: SessionObserver, info: TrialInfo, loop: Any, stopped: type[BaseException]
) -> Iterator[None]:
    """Tell `observer` of a trial that ends on an exception: `stopped` (an exception of
    type `stopped`: the session was stopped) or `interrupted`. The trial's own error is
    the one raised, even if the observer fails as well (a full disk, say)."""
    try:
        yield
    except BaseException as exc:
        status = "stopped" if isinstance(exc, stopped) else "interrupted"
        outcome = {"t_s": loop.t_s, **({} if status == "stopped" else {"reason": repr(exc)})}
        try:
            observer.trial_ended(info, status, outcome)
        except Exception:
            pass
        raise
