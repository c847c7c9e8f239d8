"""The session runner: a participant's next scheduled trials, streamed safely to the db.

For each trial still to do (the participant's blocks in order, practice trials first),
a `trials` row is committed as `running` before the first sample; samples go through
`db.samples.SampleWriter`, one committed chunk per second of trial time; the summary
and `completed` are written in one transaction at the end (a watched session waits
out another program's lock there as its sample writer does, `_write_end`). If the
process dies (kill -9, power loss), the row stays `running` with its samples up to the
last chunk; the next run of the same participant marks it `interrupted` (with an audit
entry) and repeats that trial as a new attempt, keeping the interrupted record.

One session per participant (`study.protocol.lease`): the runner holds the
participant's lease from before it recovers anything until it returns, so a second
`study run` of the same participant, here or on another lab machine, is refused with
one line while the first lives, and takes over (recovering the dead session's trial)
once it has died. A `stop` event (a `--jobs` worker whose parent died) ends the session
at its next step with the running trial marked interrupted.

Drivers: `simulated` (the participant's simulated person: the same traits in every
trial, drawn from the group's distributions with the study's seed and the code),
`hardware` (the dial's ESP32 on a serial port). The keyboard drives from the TUI.
With a fitted participant model (`participants`, MODEL.json) the simulated person is
drawn from its distributions instead, and each trial's summary names the model.
With a physical phantom (the hardware driver's real drive) the loop cannot see the tip:
a person ends the trial as reached (the dial's button, the experimenter's key), or the
time limit ends it as a failure; the summary's `end` says which (`_trial_end`).
"""

from __future__ import annotations

import contextlib
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy import Connection, Engine, func, insert, select, update
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from db.base import utcnow
from db.engine import write_transaction
from db.models.audit import AuditEntry
from db.models.study import Participant, ScheduleBlock, Study
from db.models.trial import SampleChunk, Trial, TrialMeasure
from db.samples import LOCK_POLL_MS, SampleWriter, is_lock
from study.errors import StudyInputError
from study.protocol.actor import current_actor
from study.protocol.design import MAX_TRIAL_S, StudyDesign
from study.protocol.lease import LeaseHandle, hold_lease
from study.protocol.observer import (
    PendingTrial,
    SessionInfo,
    SessionObserver,
    TrialInfo,
    session_ending,
    trial_ending,
)
from study.protocol.participant_effects import (
    ParticipantEffect,
    TrialPlace,
    apply_effects,
    session_place,
)
from study.protocol.participant_model import ParticipantModel
from study.protocol.roster import find_participant, find_study, load_study
from study.protocol.session_settings import SessionSettings
from study.protocol.stop_signals import stop_reason
from study.protocol.tasks import COMPLETION_TIME, Task, get_task
from study.protocol.traits import ParticipantTraits, draw_traits
from study.protocol.trial_run import TrialSteps, run_trial
from teleop_core.loop.drivers import Driver, DriverFailure

STEP_S = 1.0
"""Simulated time advanced between writes to the sample writer: the writer's chunk
(`chunk_s`), so each step is one committed chunk (a kill loses at most the step being
simulated) and the per-step costs (the writer's columns, the observer) come once per
chunk instead of twice."""
PACED_STEP_S = 0.05
"""The same when paced: short enough that a watcher (the TUI's live view, 20 Hz and up)
and a keyboard driver see and act at real time rather than in half-second bursts."""
HOLD_S = 300.0
"""Trial time, in s, of samples a watched session keeps in memory while another program
holds the database's lock (about 30 000 samples at 100 Hz: a few MB)."""
INTERRUPTED_BY_CRASH = "found running when a new session started (the process had died)"
STOPPED_WITH_PARENT = "the session stopped because its parent `study run` process ended"


class SessionStopped(Exception):
    """Raised inside a trial when the session's `stop` event is set."""


def participant_traits(
    study_seed: int, code: str, group: str, model: ParticipantModel | None = None
) -> ParticipantTraits:
    """The simulated person behind a code: the same in every trial and every run, drawn
    from the fitted `model`'s distributions when one is given."""
    rng = np.random.default_rng([study_seed, zlib.crc32(code.encode())])
    return draw_traits(group, rng) if model is None else model.draw(group, rng)


def recover_interrupted(
    engine: Engine,
    participant_id: int,
    reason: str = INTERRUPTED_BY_CRASH,
    actor: str | None = None,
) -> int:
    """Mark trials left `running` (by a process that died, or a trial stopped in the
    middle) as `interrupted`, with `reason` in the audit log; return how many."""
    who = current_actor(actor)
    # read-then-write: under the write lock (SQLite cannot upgrade a read transaction
    # while another process writes)
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        stale = session.scalars(
            select(Trial).where(Trial.participant_id == participant_id, Trial.status == "running")
        ).all()
        for trial in stale:
            trial.status = "interrupted"
            trial.ended_at = utcnow()
            session.add(
                AuditEntry(
                    entity="trial",
                    entity_id=trial.id,
                    field="status",
                    old_value="running",
                    new_value="interrupted",
                    reason=reason,
                    actor=who,
                )
            )
        session.commit()
    return len(stale)


def pending_trials(session: Session, participant: Participant) -> list[PendingTrial]:
    done = {
        (t.block_index, t.practice, t.trial_index)
        for t in session.scalars(
            select(Trial).where(Trial.participant_id == participant.id, Trial.status == "completed")
        )
    }
    out = []
    for block in participant.blocks:
        for practice, n in ((True, block.n_practice), (False, block.n_trials)):
            for i in range(n):
                if (block.block_index, practice, i) not in done:
                    out.append(PendingTrial(block, practice, i))
    return out


def run_session(
    engine: Engine, code: str, settings: SessionSettings, observer: SessionObserver | None = None
) -> list[int]:
    """Run the participant's remaining trials with `settings` (`SessionSettings`);
    return the ids of the trials completed.

    `observer` is told the session's events (`study.protocol.observer`): each trial's
    place (progress), its samples as they are written (the task's `sample_columns`, the
    region as its index), a wait for another program's lock (a watched session), its
    end; publishing them, recording other instruments beside the trials.
    An exception raised by the observer or the driver stops the session: the committed
    samples stay and the trial stays `running` until `recover_interrupted`.
    A set `settings.stop` ends the session at its next step, the running trial marked
    interrupted (`STOPPED_WITH_PARENT`), and returns.
    """
    actor, stop, participants = settings.actor, settings.stop, settings.participants
    study, design, participant_id = _session_start(engine, code, settings.design)
    observer = observer or SessionObserver()
    with hold_lease(engine, participant_id, code, actor) as lease, session_ending(observer):
        # read the schedule and what is done only once no other session can change it
        with Session(engine) as session:
            participant = session.get_one(Participant, participant_id)
            _ = participant.blocks  # load the schedule while the session is open
            todo = pending_trials(session, participant)
            session.expunge_all()
        reason = INTERRUPTED_BY_CRASH
        if lease.taken_over is not None:
            reason = f"found running when a new session took the lease over ({lease.taken_over})"
        recover_interrupted(engine, participant_id, reason, actor)
        tasks = {name: get_task(name) for name in sorted({p.block.task for p in todo})}
        first = tuple(tasks[name] for name in dict.fromkeys(p.block.task for p in todo))
        observer.session_started(
            SessionInfo(
                study.name, code, participant.group, settings.driver_kind, settings.pace, first
            )
        )
        contexts: dict[str, Any] = {}
        traits = participant_traits(study.seed, code, participant.group, participants)
        completed: list[int] = []
        todo = todo[: settings.max_trials] if settings.max_trials is not None else todo
        for k, item in enumerate(todo):
            lease.check()
            if stop is not None and stop.is_set():
                break
            observer.trial_progress(item, k, len(todo))
            task = tasks[item.block.task]
            if task.name not in contexts:
                contexts[task.name] = task.session_context()
            run = TrialSetup(
                task=task,
                context=contexts[task.name],
                settings=settings,
                traits=traits,
                design=design,
                study_seed=study.seed,
                check=lambda: _check_stop(lease, stop),
                model=participants.digest if participants is not None else None,
                observer=observer,
                effects=participants.participant_effects if participants is not None else (),
            )
            try:
                trial_id = _run_trial(engine, participant, item, run)
            except SessionStopped:
                recover_interrupted(
                    engine, participant_id, stop_reason(stop, STOPPED_WITH_PARENT), actor
                )
                break
            except DriverFailure as exc:
                # the device went away mid-trial: what it measured is kept, the trial
                # is interrupted now (not left running for the next session to find)
                recover_interrupted(engine, participant_id, f"the driver failed: {exc}", actor)
                raise SessionDriverError(
                    _driver_failure(engine, code, participant_id, item, exc)
                ) from None
            except (OperationalError, engine.dialect.loaded_dbapi.OperationalError) as exc:
                # a full disk, the server gone (the sample writer uses the driver's cursor)
                raise SessionStorageError(
                    _storage_failure(engine, code, participant_id, item, len(completed), exc)
                ) from exc
            if trial_id is not None:
                completed.append(trial_id)
    return completed


def _session_start(
    engine: Engine, code: str, design: StudyDesign | None
) -> tuple[Study, StudyDesign, int]:
    """The study, its design (`design`, read from the study when None) and the
    participant's id; StudyInputError for a participant who withdrew."""
    with Session(engine) as session:
        if design is None:
            study, design = load_study(session)
        else:
            study = find_study(session)
        participant = find_participant(session, study, code)
        if participant.withdrawn_at is not None:
            raise StudyInputError(
                f"participant {code} withdrew ({participant.withdrawal_reason}); "
                "expected a participant still in the study"
            )
        return study, design, participant.id


class SessionDriverError(StudyInputError):
    """The trial's device failed (a unit unplugged or silent); the trial is interrupted."""


def _driver_failure(
    engine: Engine, code: str, participant_id: int, item: PendingTrial, exc: Exception
) -> str:
    kind = "practice trial" if item.practice else "trial"
    slot = f"{item.block.task}/{item.block.condition} {kind} {item.trial_index + 1}"
    with Session(engine) as session:
        kept_s = session.scalar(
            select(func.max(SampleChunk.t_last_s))
            .join(Trial, SampleChunk.trial_id == Trial.id)
            .where(
                Trial.id
                == select(func.max(Trial.id))
                .where(Trial.participant_id == participant_id)
                .scalar_subquery()
            )
        )
    upto = "no samples" if kept_s is None else f"its samples up to t = {kept_s:.2f} s"
    return (
        f"{code}'s {slot} interrupted: {exc}; kept {upto}; expected a unit that answers "
        f"(check its cable and power, `study hardware check`), then `study run "
        f"--participant {code}` repeats the trial"
    )


class SessionStorageError(StudyInputError):
    """The database stopped taking the session's writes; the message says what was kept."""


def _storage_failure(
    engine: Engine,
    code: str,
    participant_id: int,
    item: PendingTrial,
    n_completed: int,
    exc: Exception,
) -> str:
    reason = str(getattr(exc, "orig", exc)).strip().splitlines()[0]
    kind = "practice trial" if item.practice else "trial"
    slot = f"{item.block.task}/{item.block.condition} {kind} {item.trial_index + 1}"
    try:
        with Session(engine) as session:
            kept_s = session.scalar(
                select(func.max(SampleChunk.t_last_s))
                .join(Trial, SampleChunk.trial_id == Trial.id)
                .where(Trial.participant_id == participant_id, Trial.status == "running")
            )
        upto = "no samples" if kept_s is None else f"its samples up to t = {kept_s:.2f} s"
    except OperationalError:
        upto = "the samples committed before the failure"
    return (
        f"storing {code}'s {slot} failed ({reason}): kept {n_completed} trial(s) of {code} "
        f"completed in this session and {upto} of {slot}, which the next `study run` marks "
        f"interrupted and repeats; expected {_expected_storage(exc)}"
    )


def _expected_storage(exc: BaseException) -> str:
    from db.failures import EXPECTED, classify

    return EXPECTED[classify(exc).kind]


def _check_stop(lease: LeaseHandle, stop: threading.Event | None) -> None:
    lease.check()
    if stop is not None and stop.is_set():
        raise SessionStopped


@dataclass(frozen=True)
class TrialSetup:
    """What every trial of a session shares: its task, driver and storage hooks."""

    task: Task
    context: Any
    """The task's `session_context()` (the LCCA phantom), built once per session."""
    settings: SessionSettings
    traits: ParticipantTraits
    design: StudyDesign
    study_seed: int
    check: Callable[[], None] = lambda: None
    model: str | None = None
    """The digest of the fitted participant model the traits came from, if any."""
    observer: SessionObserver = field(default_factory=SessionObserver)
    effects: tuple[ParticipantEffect, ...] = ()
    """The model's participant effects, applied to the simulated person per trial."""


def _place(participant: Participant, item: PendingTrial) -> TrialPlace:
    """Where the trial lies in the participant's session of its task."""
    blocks = sorted(
        (b for b in participant.blocks if b.task == item.block.task), key=lambda b: b.block_index
    )
    index = [b.block_index for b in blocks].index(item.block.block_index)
    return session_place(
        [b.condition for b in blocks],
        index,
        item.trial_index,
        item.block.n_trials,
        item.practice,
        item.block.n_practice,
    )


def _write_end(
    engine: Engine,
    write: Callable[[Connection], bool],
    on_wait: Callable[[float | None, int], None] | None,
) -> bool:
    """`write` in a write transaction: the trial's end, after its samples are all stored.

    Watched (`on_wait` given: the session keeps its samples through another program's
    lock, `HOLD_S`), a lock here is waited out as the sample writer waits at its close:
    attempts of `LOCK_POLL_MS` each, telling `on_wait` (the seconds waited, no samples
    held), up to `HOLD_S` of wall time, then one with the busy timeout. Else (and on
    PostgreSQL) the busy timeout alone: past it the trial stays `running`, as when its
    samples cannot be stored, for the next session to repeat."""
    if on_wait is None or engine.dialect.name != "sqlite":
        with write_transaction(engine) as conn:
            return write(conn)
    since: float | None = None
    while True:
        last = since is not None and time.monotonic() - since >= HOLD_S
        try:
            with write_transaction(engine, lock_wait_ms=None if last else LOCK_POLL_MS) as conn:
                done = write(conn)
        except OperationalError as exc:
            if last or not is_lock(exc):
                raise
            since = time.monotonic() if since is None else since
            on_wait(time.monotonic() - since, 0)
            continue
        if since is not None:
            on_wait(None, 0)
        return done


def _run_trial(
    engine: Engine, participant: Participant, item: PendingTrial, run: TrialSetup
) -> int | None:
    """Run one trial; its id, or None if it was no longer `running` at the end (another
    session took the lease over and recovered it)."""
    block, task = item.block, run.task
    # the driver first: a port that cannot be opened leaves no trial behind
    make_driver = run.settings.make_driver
    driver: Driver | None = make_driver() if make_driver else None
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        attempts = session.scalars(
            select(Trial.attempt).where(
                Trial.participant_id == participant.id,
                Trial.block_index == block.block_index,
                Trial.practice == item.practice,
                Trial.trial_index == item.trial_index,
            )
        ).all()
        trial = Trial(
            participant_id=participant.id,
            block_id=block.id,
            task=block.task,
            condition=block.condition,
            block_index=block.block_index,
            trial_index=item.trial_index,
            practice=item.practice,
            attempt=max(attempts, default=0) + 1,
            driver=run.settings.driver_kind,
            status="running",
            started_at=utcnow(),
        )
        session.add(trial)
        session.flush()
        trial_id, attempt = trial.id, trial.attempt
        session.commit()
    seed = zlib.crc32(
        f"{run.study_seed}/{participant.code}/{block.block_index}/{int(item.practice)}/"
        f"{item.trial_index}/{attempt}".encode()
    )
    gain = run.design.haptic_gain_for(block.condition) if task.has_dial else None
    if driver is None:
        traits = apply_effects(run.traits, run.effects, _place(participant, item))
        driver = task.simulated_driver(traits, MAX_TRIAL_S, run.context)
    realtime = bool(getattr(driver, "realtime", False))
    # paced or at a real device: short steps, so a watcher sees it live and a failing
    # device loses no more than a step of samples
    step_s = STEP_S if run.settings.pace is None and not realtime else PACED_STEP_S
    on_wait = run.observer.storage_wait if run.settings.wait_out_storage else None
    hold_s = HOLD_S if on_wait is not None else 0.0
    writer_at = SampleWriter(
        engine,
        trial_id,
        chunk_s=1.0,
        schema=task.sample_schema(),
        hold_s=hold_s,
        on_wait=on_wait,
    )
    with writer_at as writer, contextlib.closing(driver):
        steps = _StoredSteps(run, writer, realtime, (trial_id, block, item, attempt))
        with steps.ending():
            result = run_trial(
                task,
                block.condition,
                seed,
                driver,
                MAX_TRIAL_S,
                haptic_gain_n_m_per_n=gain,
                estimator=run.settings.estimator,
                context=run.context,
                step_s=step_s,
                steps=steps,
            )
    info, observer = steps.info, run.observer
    assert info is not None  # the trial started
    success, completion_s, ended = result.success, result.completion_time_s, result.ended
    values = result.measures
    summary = {
        **result.extras,
        **result.rendered_gain,
        "seed": seed,
        "samples": writer.rows_committed,
        **task.driver_counts(driver),
        **driver.record(),
        **({"participant_model": run.model} if run.model and make_driver is None else {}),
        **ended,
    }

    def complete(conn: Connection) -> bool:
        # only while still ours: a session that took the lease over has recovered it
        done = conn.execute(
            update(Trial)
            .where(Trial.id == trial_id, Trial.status == "running")
            .values(
                status="completed",
                ended_at=utcnow(),
                success=success,
                summary=summary,
                **{COMPLETION_TIME: completion_s},
            )
        )
        if done.rowcount == 1 and values:
            conn.execute(
                insert(TrialMeasure),
                [{"trial_id": trial_id, "name": k, "value": float(v)} for k, v in values.items()],
            )
        return done.rowcount == 1

    if _write_end(engine, complete, on_wait):
        observer.trial_ended(
            info,
            "completed",
            {"success": success, COMPLETION_TIME: completion_s, **values, **ended},
        )
        return trial_id
    observer.trial_ended(info, "interrupted", {"reason": "taken over by another session"})
    return None


class _StoredSteps(TrialSteps):
    """A session's trial step by step: each step's samples to the sample writer (one
    committed chunk per second of trial time) and the observers, paced to `pace` times
    real time, held (`TrialHold`) and stopped (`TrialSetup.check`) between two steps."""

    def __init__(
        self,
        run: TrialSetup,
        writer: SampleWriter,
        realtime: bool,
        place: tuple[int, ScheduleBlock, PendingTrial, int],
    ) -> None:
        self.run, self.writer, self.realtime, self.place = run, writer, realtime, place
        self.info: TrialInfo | None = None
        self.loop: Any = None
        self.wall0 = 0.0

    @property
    def t_s(self) -> float:
        """The running trial's time, s (0 before it started)."""
        return 0.0 if self.loop is None else float(self.loop.t_s)

    def started(self, loop: Any) -> None:
        trial_id, block, item, attempt = self.place
        self.loop, self.wall0 = loop, time.monotonic()
        self.info = TrialInfo(
            trial_id,
            self.run.task,
            block.condition,
            block.block_index,
            item.trial_index,
            item.practice,
            attempt,
            clock_origin_s=self.wall0,
            clock_rate=self.run.settings.pace or 1.0,
            realtime=self.run.settings.pace is not None or self.realtime,
        )
        self.run.observer.trial_started(self.info)

    def before_step(self, loop: Any) -> None:
        hold = self.run.settings.hold
        if hold is not None and hold.held:
            self.writer.flush()  # what the trial measured so far is stored while it stands
            self.wall0 += hold.wait()  # held time is not trial time: no catching up
        self.run.check()

    def after_step(self, loop: Any, samples: np.ndarray) -> None:
        run = self.run
        if len(samples):
            self.writer.extend(run.task.stored_columns(samples))
        assert self.info is not None  # started before the first step
        run.observer.samples(self.info, samples)
        pace = run.settings.pace
        if pace:
            lag = self.wall0 + loop.t_s / pace - time.monotonic()
            if lag > 0:
                time.sleep(lag)

    def finished(self, loop: Any) -> None:
        self.writer.flush()  # every sample committed before the trial is measured

    @contextlib.contextmanager
    def ending(self) -> Iterator[None]:
        """Tell the observers of a trial that started and ends on an exception
        (`trial_ending`: stopped or interrupted)."""
        try:
            yield
        except BaseException:
            if self.info is None:
                raise
            with trial_ending(self.run.observer, self.info, self, SessionStopped):
                raise
