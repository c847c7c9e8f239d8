"""Simulating trait settings through a task's own trials, in parallel processes.

The fit's only contact with the simulation: a list of trait settings goes in, one row
per (setting, condition, repeat) with the task's analysed measures comes out. Each
trial is `Task.simulate` (the registry's task, its loop, its simulated driver and, for a
task with a dial, the shipped force estimator), as `study simulate` and campaigns run
it, so a task added to the registry is fitted through the same path.

Common random numbers across conditions: VO and HV of one (setting, repeat) run with the
same trial seed, so their difference is the condition's alone. Across settings the
seeds differ: with one set of seeds shared by every setting, the emulator's surface
would carry those few seeds' luck into every prediction (a bias of the order of the
trial noise over the square root of the repeats), while independent seeds let the
regression average the trial noise over hundreds of trials.

The processes are `concurrent.futures` workers (spawn, as `study run --jobs`), each
warming up once (its imports, the loop's compiled kernel, the estimator: as much CPU
as a few settings' trials); one job is one setting with all its trials,
so the work is coarse enough that the pool costs nothing beyond that start-up. A fit
simulates twice (the emulator's design, then people drawn from the fit): `worker_pool`
keeps one pool open across both, so that its workers start once.
Each row also holds the task's `fit_features` of the trial's samples, read off the
simulated frame as `observed.py` reads them off the stored samples.
"""

from __future__ import annotations

import multiprocessing
import os
import zlib
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import AbstractContextManager, contextmanager, nullcontext
from contextvars import ContextVar
from functools import lru_cache
from typing import Any

import pandas as pd

from study.protocol.design import KNOWN_CONDITIONS, MAX_TRIAL_S
from study.protocol.participant_effects import ParticipantEffect, apply_effects, session_place
from study.protocol.tasks import get_task
from study.protocol.traits import ParticipantTraits
from study.protocol.trial_run import simulate_trial
from teleop_core.progress import Progress, no_progress


def trial_seed(setting: int, repeat: int, salt: str = "fit", condition: str = "") -> int:
    """The seed of a setting's repeat `repeat`: the same in both conditions unless
    `condition` is given (a simulated study's people, whose VO and HV trials are
    independent as a real session's are)."""
    return zlib.crc32(f"{salt}/{setting}/{repeat}{'/' + condition if condition else ''}".encode())


@lru_cache(maxsize=1)
def _estimator() -> Any:
    # lazy: study.protocol.default_estimator costs 36 ms at start-up
    from study.protocol.default_estimator import load_estimator

    return load_estimator()


@lru_cache(maxsize=4)
def _context(task: str) -> Any:
    return get_task(task).session_context()


def simulate_setting(
    task: str,
    index: int,
    setting: dict[str, Any],
    repeats: int,
    max_s: float,
    salt: str = "fit",
    effects: Sequence[ParticipantEffect] = (),
) -> list[dict[str, Any]]:
    """Every trial of one trait setting (`group` plus the traits, and `first`: the
    condition of the person's first block where `effects` apply): each condition x
    repeat, with the task's analysed measures and `success`. With the salt `fit` both
    conditions share a repeat's seed; with any other, each trial has its own."""
    the_task = get_task(task)
    setting = dict(setting)
    first = setting.pop("first", KNOWN_CONDITIONS[0])
    person = ParticipantTraits(**setting)
    order = [first, *(c for c in KNOWN_CONDITIONS if c != first)]
    estimator = _estimator() if the_task.has_dial else None
    rows = []
    for r in range(repeats):
        for condition in KNOWN_CONDITIONS:
            place = session_place(order, order.index(condition), r, repeats)
            traits = apply_effects(person, effects, place)
            result = simulate_trial(
                the_task,
                traits,
                condition,
                trial_seed(index, r, salt, "" if salt == "fit" else condition),
                max_s,
                estimator=estimator,
                context=_context(task),
            )
            s = result.summary
            rows.append(
                {
                    "condition": condition,
                    "repeat": r,
                    "success": bool(s["success"]),
                    **{m: float(s[m]) for m in the_task.analysed_measures},
                    **the_task.trial_features(result.frame, _context(task)),
                }
            )
    return rows


def _warm(task: str, parent_pid: int | None = None) -> None:
    if parent_pid is not None:  # else a killed fit's workers wait for tasks for good
        from study.protocol.parallel import watch_parent

        watch_parent(parent_pid)
    the_task = get_task(task)
    _context(task)
    if the_task.has_dial:
        _estimator()


_POOL: ContextVar[tuple[str, int, ProcessPoolExecutor] | None] = ContextVar("pool", default=None)
"""The pool `worker_pool` holds open: (task, workers, executor)."""


def _new_pool(task: str, jobs: int) -> ProcessPoolExecutor:
    context = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(
        jobs, mp_context=context, initializer=_warm, initargs=(task, os.getpid())
    )


@contextmanager
def worker_pool(task: str, jobs: int) -> Iterator[None]:
    """Within it, `simulate_settings` of `task` with `jobs` workers runs on one pool,
    started here (its workers start up while the caller goes on) and shut down at the
    end, instead of a pool of its own per call."""
    if jobs <= 1:
        yield
        return
    with _new_pool(task, jobs) as pool:
        for _ in range(jobs):  # start the workers now, beside the caller's own work
            pool.submit(int)
        token = _POOL.set((task, jobs, pool))
        try:
            yield
        finally:
            _POOL.reset(token)


def simulate_settings(
    task: str,
    settings: Sequence[dict[str, Any]],
    repeats: int,
    jobs: int = 1,
    max_s: float = MAX_TRIAL_S,
    progress: Progress = no_progress,
    salt: str = "fit",
    effects: Sequence[ParticipantEffect] = (),
) -> pd.DataFrame:
    """One row per trial of every setting: `setting` (its index), condition, repeat,
    success, the task's analysed measures and fit features; `progress("simulating", k, n)`
    after each setting."""
    rows: list[dict[str, Any]] = []
    n = len(settings)
    if jobs <= 1 or n <= 1:
        for k, setting in enumerate(settings):
            rows += [
                {"setting": k, **row}
                for row in simulate_setting(task, k, setting, repeats, max_s, salt, effects)
            ]
            progress("simulating", k + 1, n)
    else:
        shared = _POOL.get()
        opened: AbstractContextManager[object]
        if shared is not None and shared[:2] == (task, jobs):
            opened, pool = nullcontext(), shared[2]
        else:
            pool = _new_pool(task, jobs)
            opened = pool
        with opened:
            futures = {
                pool.submit(simulate_setting, task, k, s, repeats, max_s, salt, effects): k
                for k, s in enumerate(settings)
            }
            for done, future in enumerate(as_completed(futures), 1):
                rows += [{"setting": futures[future], **row} for row in future.result()]
                progress("simulating", done, n)
    frame = pd.DataFrame(rows)
    return frame.sort_values(["setting", "repeat", "condition"], kind="stable").reset_index(
        drop=True
    )
