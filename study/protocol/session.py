"""The session runner: a participant's next scheduled trials, streamed safely to the db.

For each trial still to do (the participant's blocks in order, practice trials first),
a `trials` row is committed as `running` before the first sample; samples go through
`db.samples.SampleWriter`, one committed chunk per second of trial time; the summary
and `completed` are written in one transaction at the end. If the process dies (kill
-9, power loss), the row stays `running` with its samples up to the last chunk; the
next run of the same participant marks it `interrupted` (with an audit entry) and
repeats that trial as a new attempt, keeping the interrupted record.

Drivers: `simulated` (the participant's simulated person: the same traits in every
trial, drawn from the group's distributions with the study's seed and the code),
`hardware` (the dial's ESP32 on a serial port). The keyboard drives from the TUI.
"""

from __future__ import annotations

import multiprocessing
import time
import zlib
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import Engine, select, update
from sqlalchemy.orm import Session

from db.base import utcnow
from db.engine import write_transaction
from db.models.audit import AuditEntry
from db.models.study import Participant, ScheduleBlock
from db.models.trial import Trial
from db.samples import SampleWriter
from study.errors import StudyInputError
from study.protocol.lcca_trial import lcca_loop, measures, trial_frame
from study.protocol.notes_trial import NotesParticipant, notes_loop
from study.protocol.notes_trial import measures as notes_measures
from study.protocol.notes_trial import trial_frame as notes_trial_frame
from study.protocol.participants import ParticipantTraits, SimulatedParticipant, draw_traits
from study.protocol.roster import find_participant, load_study
from teleop_core.estimation.estimator import ForceEstimator
from teleop_core.loop.core import SAMPLE_COLUMNS, TeleopLoop
from teleop_core.loop.drivers import Driver
from teleop_core.notes.task import REGIONS as NOTES_REGIONS
from teleop_core.notes.task import NotesLoop
from teleop_core.phantom.anatomy import REGION_ABBREVIATIONS
from teleop_core.phantom.lcca import LccaPhantom

MAX_TRIAL_S = 180.0
"""A trial ends unsuccessfully after this long."""
STEP_S = 0.5
"""Simulated time advanced between writes to the sample writer."""
PACED_STEP_S = 0.05
"""The same when paced: short enough that a watcher (the TUI's live view, 20 Hz and up)
and a keyboard driver see and act at real time rather than in half-second bursts."""
INTERRUPTED_BY_CRASH = "found running when a new session started (the process had died)"


@dataclass(frozen=True)
class PendingTrial:
    block: ScheduleBlock
    practice: bool
    trial_index: int


def participant_traits(study_seed: int, code: str, group: str) -> ParticipantTraits:
    """The simulated person behind a code: the same in every trial and every run."""
    return draw_traits(group, np.random.default_rng([study_seed, zlib.crc32(code.encode())]))


def recover_interrupted(
    engine: Engine, participant_id: int, reason: str = INTERRUPTED_BY_CRASH
) -> int:
    """Mark trials left `running` (by a process that died, or a trial stopped in the
    middle) as `interrupted`, with `reason` in the audit log; return how many."""
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
) -> list[int]:
    """Run the participant's remaining trials; return the ids of the trials completed.

    `pace` slows a simulated session to `pace` times real time (to watch it, or to stop
    it in the middle); `on_trial(pending, k, n)` reports progress; `on_samples(rows)`
    sees every batch of samples (SAMPLE_COLUMNS, branch as its code) as it is written.
    An exception raised by a callback or the driver stops the session: the committed
    samples stay and the trial stays `running` until `recover_interrupted`.
    """
    with Session(engine) as session:
        study, _ = load_study(session)
        participant = find_participant(session, study, code)
        _ = participant.blocks  # load the schedule while the session is open
        todo = pending_trials(session, participant)
        session.expunge_all()
    recover_interrupted(engine, participant.id)
    unknown = sorted({p.block.task for p in todo} - {"lcca", "notes"})
    if unknown:
        raise StudyInputError(f"task {unknown[0]!r} in the schedule; expected lcca or notes")
    phantom = LccaPhantom()
    traits = participant_traits(study.seed, code, participant.group)
    completed: list[int] = []
    todo = todo[:max_trials] if max_trials is not None else todo
    for k, item in enumerate(todo):
        on_trial(item, k, len(todo))
        completed.append(
            _run_trial(
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
            )
        )
    return completed


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
) -> int:
    block = item.block
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
        driver = make_driver() if make_driver else NotesParticipant(traits, MAX_TRIAL_S)
        regions = NOTES_REGIONS
    else:
        loop = lcca_loop(block.condition, seed, estimator, phantom=phantom)
        driver = (
            make_driver() if make_driver else SimulatedParticipant(traits, phantom, MAX_TRIAL_S)
        )
        regions = REGION_ABBREVIATIONS
    loop.start(driver)
    chunks = []
    step_s = STEP_S if pace is None else PACED_STEP_S
    wall0 = time.monotonic()
    with SampleWriter(engine, trial_id, chunk_s=1.0) as writer:
        while loop.t_s < MAX_TRIAL_S - 1e-9 and not loop.done:
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
        conn.execute(
            update(Trial)
            .where(Trial.id == trial_id)
            .values(status="completed", ended_at=utcnow(), **values)
        )
    return trial_id


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


def _worker_init(db_url: str | None) -> None:
    from db.migrate import open_database
    from study.protocol.default_estimator import load_estimator

    _WORKER["engine"] = open_database(db_url, create=False)
    _WORKER["estimator"] = load_estimator()


def _worker_run(code: str) -> tuple[str, int]:
    engine, estimator = _WORKER["engine"], _WORKER["estimator"]
    return code, len(run_session(engine, code, "simulated", estimator))  # type: ignore[arg-type]


def run_participants(
    db_url: str | None, codes: list[str], jobs: int, pace: float | None = None
) -> Iterator[tuple[str, int]]:
    """Run simulated sessions for `codes` in `jobs` processes; yield (code, trials) as each
    finishes. Each process opens its own connection and loads the estimator once."""
    if jobs == 1 or pace is not None:
        _worker_init(db_url)
        for code in codes:
            engine, estimator = _WORKER["engine"], _WORKER["estimator"]
            yield code, len(run_session(engine, code, "simulated", estimator, pace=pace))  # type: ignore[arg-type]
        return
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        jobs, mp_context=context, initializer=_worker_init, initargs=(db_url,)
    ) as pool:
        futures = [pool.submit(_worker_run, code) for code in codes]
        for future in as_completed(futures):
            yield future.result()
