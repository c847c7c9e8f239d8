"""The session runner: a participant's next scheduled trials, streamed safely to the db.

For each trial still to do (the participant's blocks in order, practice trials first),
a `trials` row is committed as `running` before the first sample; samples go through
`db.samples.SampleWriter`, one committed chunk per second of trial time; the summary
and `completed` are written in one transaction at the end. If the process dies (kill
-9, power loss), the row stays `running` with its samples up to the last chunk; the
next run of the same participant marks it `interrupted` (with an audit entry) and
repeats that trial as a new attempt, keeping the interrupted record.

One session per participant (`study.protocol.lease`): the runner holds the
participant's lease from before it recovers anything until it returns, so a second
`study run` of the same participant, here or on another lab machine, is refused with
one line while the first lives, and takes over (recovering the dead session's trial)
once it has died. A `stop` event (a `--jobs` worker whose parent died) ends the session
at its next step with the running trial marked interrupted.

Drivers: `simulated` (the participant's simulated person: the same traits in every
trial, drawn from the group's distributions with the study's seed and the code),
`hardware` (the dial's ESP32 on a serial port). The keyboard drives from the TUI.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import Engine, func, select, update
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from db.base import utcnow
from db.engine import write_transaction
from db.models.audit import AuditEntry
from db.models.study import Participant, ScheduleBlock
from db.models.trial import Sample, Trial
from db.samples import SampleWriter
from study.errors import StudyInputError
from study.protocol.actor import current_actor
from study.protocol.design import MAX_TRIAL_S
from study.protocol.lcca_trial import lcca_loop, measures, trial_frame
from study.protocol.notes_trial import NotesParticipant, notes_loop
from study.protocol.notes_trial import measures as notes_measures
from study.protocol.notes_trial import trial_frame as notes_trial_frame
from study.protocol.lease import LeaseHandle, hold_lease
from study.protocol.participants import ParticipantTraits, SimulatedParticipant, draw_traits
from study.protocol.roster import find_participant, load_study
from teleop_core.estimation.estimator import ForceEstimator
from teleop_core.loop.core import SAMPLE_COLUMNS, TeleopLoop
from teleop_core.loop.drivers import Driver
from teleop_core.notes.task import REGIONS as NOTES_REGIONS
from teleop_core.notes.task import NotesLoop
from teleop_core.phantom.anatomy import REGION_ABBREVIATIONS
from teleop_core.phantom.lcca import LccaPhantom

STEP_S = 0.5
"""Simulated time advanced between writes to the sample writer."""
PACED_STEP_S = 0.05
"""The same when paced: short enough that a watcher (the TUI's live view, 20 Hz and up)
and a keyboard driver see and act at real time rather than in half-second bursts."""
INTERRUPTED_BY_CRASH = "found running when a new session started (the process had died)"
STOPPED_WITH_PARENT = "the session stopped because its parent `study run` process ended"


class SessionStopped(Exception):
    """Raised inside a trial when the session's `stop` event is set."""


@dataclass(frozen=True)
class PendingTrial:
    block: ScheduleBlock
    practice: bool
    trial_index: int


def participant_traits(study_seed: int, code: str, group: str) -> ParticipantTraits:
    """The simulated person behind a code: the same in every trial and every run."""
    return draw_traits(group, np.random.default_rng([study_seed, zlib.crc32(code.encode())]))


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


def _sample_columns(samples: np.ndarray, regions: tuple[str, ...]) -> dict[str, list[object]]:
    cols = {name: samples[:, k].tolist() for k, name in enumerate(SAMPLE_COLUMNS)}
    cols["branch"] = [regions[int(c)] for c in cols["branch"]]
    return cols


def run_session(
    engine: Engine,
    code: str,
    driver_kind: str,
    estimator: ForceEstimator,
    make_driver: Callable[[], Driver] | None = None,
    pace: float | None = None,
    on_trial: Callable[[PendingTrial, int, int], None] = lambda *_: None,
    max_trials: int | None = None,
    on_samples: Callable[[np.ndarray], None] | None = None,
    actor: str | None = None,
    stop: threading.Event | None = None,
) -> list[int]:
    """Run the participant's remaining trials; return the ids of the trials completed.

    `pace` slows a simulated session to `pace` times real time (to watch it, or to stop
    it in the middle); `on_trial(pending, k, n)` reports progress; `on_samples(rows)`
    sees every batch of samples (SAMPLE_COLUMNS, branch as its code) as it is written.
    An exception raised by a callback or the driver stops the session: the committed
    samples stay and the trial stays `running` until `recover_interrupted`.
    `actor` is recorded with the lease; a set `stop` ends the session at its next step,
    the running trial marked interrupted (`STOPPED_WITH_PARENT`), and returns.
    """
    if pace is not None and not (math.isfinite(pace) and pace > 0):
        raise StudyInputError(f"pace {pace!r}; expected a finite number > 0 (times real time)")
    with Session(engine) as session:
        study, _ = load_study(session)
        participant = find_participant(session, study, code)
        participant_id = participant.id
        if participant.withdrawn_at is not None:
            raise StudyInputError(
                f"participant {code} withdrew ({participant.withdrawal_reason}); "
                "expected a participant still in the study"
            )
    with hold_lease(engine, participant_id, code, actor) as lease:
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
        unknown = sorted({p.block.task for p in todo} - {"lcca", "notes"})
        if unknown:
            raise StudyInputError(f"task {unknown[0]!r} in the schedule; expected lcca or notes")
        phantom = LccaPhantom()
        traits = participant_traits(study.seed, code, participant.group)
        completed: list[int] = []
        todo = todo[:max_trials] if max_trials is not None else todo
        for k, item in enumerate(todo):
            lease.check()
            if stop is not None and stop.is_set():
                break
            on_trial(item, k, len(todo))
            try:
                trial_id = _run_trial(
                    engine,
                    participant,
                    item,
                    driver_kind,
                    estimator,
                    traits,
                    phantom,
                    make_driver,
                    pace,
                    study.seed,
                    on_samples,
                    lambda: _check_stop(lease, stop),
                )
            except SessionStopped:
                recover_interrupted(engine, participant_id, STOPPED_WITH_PARENT, actor)
                break
            except (OperationalError, engine.dialect.dbapi.OperationalError) as exc:
                # a full disk, the server gone (the sample writer uses the driver's cursor)
                raise SessionStorageError(
                    _storage_failure(engine, participant_id, item, len(completed), exc)
                ) from exc
            if trial_id is not None:
                completed.append(trial_id)
    return completed


class SessionStorageError(StudyInputError):
    """The database stopped taking the session's writes; the message says what was kept."""


def _storage_failure(
    engine: Engine, participant_id: int, item: PendingTrial, n_completed: int, exc: Exception
) -> str:
    reason = str(getattr(exc, "orig", exc)).strip().splitlines()[0]
    kind = "practice trial" if item.practice else "trial"
    slot = f"{item.block.task}/{item.block.condition} {kind} {item.trial_index + 1}"
    try:
        with Session(engine) as session:
            kept_s = session.scalar(
                select(func.max(Sample.t_s))
                .join(Trial, Sample.trial_id == Trial.id)
                .where(Trial.participant_id == participant_id, Trial.status == "running")
            )
        upto = "no samples" if kept_s is None else f"its samples up to t = {kept_s:.2f} s"
    except OperationalError:
        upto = "the samples committed before the failure"
    return (
        f"storing {slot} failed ({reason}): kept {n_completed} trial(s) completed in this "
        f"session and {upto} of {slot}, which the next `study run` marks interrupted and "
        "repeats; expected a database with free space"
    )


def _check_stop(lease: LeaseHandle, stop: threading.Event | None) -> None:
    lease.check()
    if stop is not None and stop.is_set():
        raise SessionStopped


def _driver_counts(driver: Driver) -> dict[str, int]:
    """What a simulated participant noticed during the trial (by hand, by eye)."""
    if isinstance(driver, SimulatedParticipant):
        return {"obstacles_felt": driver.obstacles_felt, "obstacles_seen": driver.obstacles_seen}
    if isinstance(driver, NotesParticipant):
        return {"stalls_seen": driver.stalls_seen}
    return {}


def _run_trial(
    engine: Engine,
    participant: Participant,
    item: PendingTrial,
    driver_kind: str,
    estimator: ForceEstimator,
    traits: ParticipantTraits,
    phantom: LccaPhantom,
    make_driver: Callable[[], Driver] | None,
    pace: float | None,
    study_seed: int,
    on_samples: Callable[[np.ndarray], None] | None = None,
    check: Callable[[], None] = lambda: None,
) -> int | None:
    """Run one trial; its id, or None if it was no longer `running` at the end (another
    session took the lease over and recovered it)."""
    block = item.block
    # the driver first: a port that cannot be opened leaves no trial behind
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
            driver=driver_kind,
            status="running",
            started_at=utcnow(),
        )
        session.add(trial)
        session.flush()
        trial_id, attempt = trial.id, trial.attempt
        session.commit()
    seed = zlib.crc32(
        f"{study_seed}/{participant.code}/{block.block_index}/{int(item.practice)}/"
        f"{item.trial_index}/{attempt}".encode()
    )
    loop: TeleopLoop | NotesLoop
    if block.task == "notes":
        # the NOTES loop's first columns are the database's sample columns
        loop = notes_loop(block.condition, seed)
        if driver is None:
            driver = NotesParticipant(traits, MAX_TRIAL_S)
        regions = NOTES_REGIONS
    else:
        loop = lcca_loop(block.condition, seed, estimator, phantom=phantom)
        if driver is None:
            driver = SimulatedParticipant(traits, phantom, MAX_TRIAL_S)
        regions = REGION_ABBREVIATIONS
    loop.start(driver)
    chunks = []
    step_s = STEP_S if pace is None else PACED_STEP_S
    wall0 = time.monotonic()
    with SampleWriter(engine, trial_id, chunk_s=1.0) as writer:
        while loop.t_s < MAX_TRIAL_S - 1e-9 and not loop.done:
            check()
            samples = loop.advance(min(step_s, MAX_TRIAL_S - loop.t_s))
            if len(samples):
                writer.extend(_sample_columns(samples, regions))
                chunks.append(samples)
                if on_samples is not None:
                    on_samples(samples)
            if pace:
                lag = wall0 + loop.t_s / pace - time.monotonic()
                if lag > 0:
                    time.sleep(lag)
    if block.task == "notes":
        values = _notes_values(np.concatenate(chunks), loop.success)
    else:
        values = _lcca_values(np.concatenate(chunks), loop.success)
    values["summary"] = {
        **values["summary"],
        "seed": seed,
        "samples": writer.rows_committed,
        **_driver_counts(driver),
    }
    with write_transaction(engine) as conn:
        # only while still ours: a session that took the lease over has recovered it
        done = conn.execute(
            update(Trial)
            .where(Trial.id == trial_id, Trial.status == "running")
            .values(status="completed", ended_at=utcnow(), **values)
        )
    return trial_id if done.rowcount == 1 else None


def _lcca_values(samples: np.ndarray, success: bool) -> dict[str, Any]:
    raw = pd.DataFrame(samples, columns=list(SAMPLE_COLUMNS))
    result = measures(trial_frame(raw), success)
    return {
        "completion_time_s": result["completion_time_s"],
        "peak_proximal_force_n": max(result["peak_proximal_force_n"], 0.0),
        "peak_distal_force_n": max(result["peak_distal_force_n"], 0.0),
        "success": result["success"],
        "wall_contacts": result["wall_contacts"],
        "summary": {"peak_proximal_reference_force_n": result["peak_proximal_reference_force_n"]},
    }


def _notes_values(samples: np.ndarray, success: bool) -> dict[str, Any]:
    """NOTES measures in the trial columns (see study.protocol.notes_trial)."""
    result = notes_measures(notes_trial_frame(samples), success)
    summary = {
        k: v
        for k, v in result.items()
        if k not in ("success", "completion_time_s", "peak_force_demanded_n", "peak_tip_force_n")
    }
    return {
        "completion_time_s": result["completion_time_s"],
        "peak_proximal_force_n": result["peak_force_demanded_n"],
        "peak_distal_force_n": result["peak_tip_force_n"],
        "success": result["success"],
        "wall_contacts": None,
        "summary": summary,
    }


_WORKER: dict[str, object] = {}
PARENT_POLL_S = 0.5
"""How often a `--jobs` worker checks that its parent is alive."""
STOP_GRACE_S = 10.0
"""How long a worker whose parent died may take to mark its trial and leave."""


def _watch_parent(parent_pid: int, stop: threading.Event, idle: threading.Event) -> None:
    """End this worker when its parent dies (issue 18: after `kill -9` of `study run
    --all --jobs 2` the workers kept running and writing). The session stops at its next
    step and marks its trial interrupted; a worker stuck longer exits hard, which leaves
    a lease of a gone process that the next run takes over at once."""
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    stop.set()
    idle.wait(STOP_GRACE_S)
    os._exit(1)


def _worker_init(
    db_url: str | None, parent_pid: int | None = None, actor: str | None = None
) -> None:
    from db.migrate import open_database
    from study.protocol.default_estimator import load_estimator

    _WORKER["engine"] = open_database(db_url, create=False)
    _WORKER["estimator"] = load_estimator()
    _WORKER["actor"] = actor
    stop, idle = threading.Event(), threading.Event()
    idle.set()
    _WORKER["stop"], _WORKER["idle"] = stop, idle
    if parent_pid is not None:
        threading.Thread(
            target=_watch_parent, args=(parent_pid, stop, idle), name="parent-watch", daemon=True
        ).start()


def _worker_run(code: str, pace: float | None = None) -> tuple[str, int]:
    idle: threading.Event = _WORKER["idle"]  # type: ignore[assignment]
    idle.clear()
    try:
        done = run_session(
            _WORKER["engine"],  # type: ignore[arg-type]
            code,
            "simulated",
            _WORKER["estimator"],  # type: ignore[arg-type]
            pace=pace,
            actor=_WORKER["actor"],  # type: ignore[arg-type]
            stop=_WORKER["stop"],  # type: ignore[arg-type]
        )
    finally:
        idle.set()
    return code, len(done)


def run_participants(
    db_url: str | None,
    codes: list[str],
    jobs: int,
    pace: float | None = None,
    actor: str | None = None,
    on_busy: Callable[[str, str], None] | None = None,
) -> Iterator[tuple[str, int]]:
    """Run simulated sessions for `codes` in `jobs` processes; yield (code, trials) as each
    finishes. Each process opens its own connection and loads the estimator once, and
    ends when this process dies.

    A participant whose session runs elsewhere (`SessionBusyError`) is skipped and
    reported through `on_busy(code, message)` (raised when `on_busy` is None).
    """
    from study.protocol.lease import SessionBusyError

    def busy(code: str, exc: SessionBusyError) -> tuple[str, int]:
        if on_busy is None:
            raise exc
        on_busy(code, str(exc))
        return code, 0

    if jobs == 1:
        _worker_init(db_url, actor=actor)
        for code in codes:
            try:
                yield _worker_run(code, pace)
            except SessionBusyError as exc:
                yield busy(code, exc)
        return
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        jobs, mp_context=context, initializer=_worker_init, initargs=(db_url, os.getpid(), actor)
    ) as pool:
        futures = {pool.submit(_worker_run, code, pace): code for code in codes}
        for future in as_completed(futures):
            try:
                yield future.result()
            except SessionBusyError as exc:
                yield busy(futures[future], exc)
