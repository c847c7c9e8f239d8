"""One trial from the terminal: the session runner in a worker thread, watched and stoppable.

The trial itself is `study.protocol.session.run_session` with `max_trials=1`: the same
`running` row, the same 1 s committed sample chunks, the same summary as `study run`.
This module adds what a terminal needs around it:

- `LiveState`: the newest samples, written by the worker (`on_samples`) and read by the
  live view's timer; a lock guards the hand-over, so the UI never waits on the trial.
- stopping: `TrialRun.stop()` sets an event; the next batch of samples (50 ms of trial
  time when paced) raises `TrialStopped` inside the runner, the sample writer commits
  what it holds, and the trial is marked `interrupted` with `recover_interrupted` (an
  audit entry says why). Closing the app mid-trial goes the same way.
- `TuiKeyboardDriver`: `teleop_core`'s `KeyboardDriver`, ending the trial when the tip
  reaches the target (a person at the keys sees it on the screen). It drives NOTES
  blocks too: the NOTES loop reads the same `Driver` (the dial's aim sets the scope's
  insertion speed, the rotation keys its roll).

LCCA and NOTES samples differ by one column (`teleop_core.notes.task.SAMPLE_COLUMNS`
adds the demanded torque), which is how `LiveState` tells them apart.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from teleop_core.loop.drivers import HandAction, KeyboardDriver, OperatorView

STOPPED_REASON = "stopped from the terminal app in the middle of the trial"
HISTORY_S = 6.0
"""Seconds of force history the live plots keep."""


class Simulation:
    """The estimator and the compiled loop, made ready once per app (in a worker).

    The first advance of a loop in a process compiles its kernel with the phantom
    (several seconds); `ready()` pays that on a throwaway loop with no database, so the
    first trial starts at once. Thread-safe: a trial that starts while the app is still
    preparing waits for it instead of doing it twice.
    """

    def __init__(self, load_estimator: Callable[[], object]) -> None:
        self._load = load_estimator
        self._lock = threading.Lock()
        self.estimator: object | None = None

    def ready(self) -> object:
        """The estimator, after the loop's kernel has been compiled."""
        with self._lock:
            if self.estimator is None:
                from study.protocol.lcca_trial import lcca_loop
                from teleop_core.loop.drivers import SimulatedOperator

                estimator = self._load()
                loop = lcca_loop("HV", 0, estimator)  # type: ignore[arg-type]
                loop.start(SimulatedOperator())
                loop.advance(0.05)
                self.estimator = estimator
            return self.estimator


class TrialStopped(Exception):
    """Raised inside the runner to stop the trial (not an error of the user's input)."""


class TuiKeyboardDriver(KeyboardDriver):
    """Keys turn the dial and the joystick; reaching the target ends the trial."""

    def act(self, view: OperatorView) -> HandAction:
        action = super().act(view)
        if view.success and not action.done:
            return HandAction(done=True)
        return action


@dataclass(frozen=True)
class LiveFrame:
    """What the live view draws at one redraw.

    LCCA: `proximal_n` is the estimate the robot renders (what the study reports),
    `distal_n` the tip's force; the histories are these two. NOTES (the loop's columns
    read the NOTES way, `teleop_core.notes.task`): `proximal_n` is the force the device
    renders, `demanded_n` the force the tissue demands, `distal_n` the tip's force on
    the fornix, `dial_torque_n_m` the rendered torque, `branch` an index into the NOTES
    regions; the histories are the demanded and the rendered force's magnitudes.
    """

    t_s: float
    tip_xz_m: tuple[float, float]
    branch: int
    insertion_m: float
    rotation_rad: float
    proximal_n: float
    distal_n: float
    dial_angle_rad: float
    dial_torque_n_m: float
    proximal_history_n: tuple[float, ...]
    distal_history_n: tuple[float, ...]
    task: str = "lcca"
    demanded_n: float = math.nan
    torque_demanded_n_m: float = math.nan


def _columns(width: int) -> tuple[str, dict[str, int]]:
    """(task, sample column -> index) for samples `width` columns wide (imported on first
    use: the loop's module loads torch)."""
    from teleop_core.loop.core import SAMPLE_COLUMNS
    from teleop_core.notes.task import SAMPLE_COLUMNS as NOTES_COLUMNS

    for task, columns in (("lcca", SAMPLE_COLUMNS), ("notes", NOTES_COLUMNS)):
        if width == len(columns):
            return task, {name: k for k, name in enumerate(columns)}
    raise ValueError(
        f"samples with {width} columns; expected {len(SAMPLE_COLUMNS)} (LCCA) "
        f"or {len(NOTES_COLUMNS)} (NOTES)"
    )


TRACES = {
    "lcca": ("proximal_force_est_n", "distal_force_n"),
    "notes": ("proximal_force_n", "proximal_force_est_n"),
}
"""The two force traces the live view plots, per task (NOTES: demanded, rendered)."""
PEAKS = {
    "lcca": ("proximal_force_est_n", "distal_force_n"),
    "notes": ("proximal_force_n", "distal_force_n"),
}
"""The columns of the two peaks shown when a trial ends: as the trial's stored
peak_proximal_force_n / peak_distal_force_n (NOTES: demanded force, tip force)."""


class LiveState:
    """The newest samples of the running trial, handed from the worker to the view."""

    def __init__(self, rate_hz: float = 100.0) -> None:
        self._col: dict[str, int] = {}
        self.task: str | None = None
        """"lcca" or "notes", known from the first batch."""
        self._lock = threading.Lock()
        self._last: np.ndarray | None = None
        n = round(HISTORY_S * rate_hz)
        self._prox: deque[float] = deque(maxlen=n)
        self._dist: deque[float] = deque(maxlen=n)
        self.batches = 0
        self.peak_proximal_n = 0.0
        self.peak_distal_n = 0.0

    def push(self, samples: np.ndarray) -> None:
        """Take a batch of samples (in the worker); the first call resolves the columns."""
        if not self._col:
            self.task, self._col = _columns(samples.shape[1])
        COL, task = self._col, self.task or "lcca"
        first, second, *peaks = (samples[:, COL[c]] for c in TRACES[task] + PEAKS[task])
        if task == "notes":  # pushes and pulls alike, as the NOTES summary's peaks
            first, second, *peaks = (np.abs(v) for v in (first, second, *peaks))
        with self._lock:
            self._last = samples[-1].copy()
            self._prox.extend(first.tolist())
            self._dist.extend(second.tolist())
            self.batches += 1
            self.peak_proximal_n = max(self.peak_proximal_n, float(peaks[0].max()))
            self.peak_distal_n = max(self.peak_distal_n, float(peaks[1].max()))

    def frame(self) -> LiveFrame | None:
        with self._lock:
            row = self._last
            if row is None:
                return None
            prox, dist = tuple(self._prox), tuple(self._dist)
        COL = self._col
        notes = self.task == "notes"
        return LiveFrame(
            t_s=float(row[COL["t_s"]]),
            tip_xz_m=(float(row[COL["tip_x_m"]]), float(row[COL["tip_z_m"]])),
            branch=int(row[COL["branch"]]),
            insertion_m=float(row[COL["insertion_m"]]),
            rotation_rad=float(row[COL["rotation_rad"]]),
            proximal_n=float(row[COL["proximal_force_est_n"]]),
            distal_n=float(row[COL["distal_force_n"]]),
            dial_angle_rad=float(row[COL["dial_angle_rad"]]),
            dial_torque_n_m=float(row[COL["dial_torque_n_m"]]),
            proximal_history_n=prox,
            distal_history_n=dist,
            task=self.task or "lcca",
            demanded_n=float(row[COL["proximal_force_n"]]) if notes else math.nan,
            torque_demanded_n_m=float(row[COL["torque_demanded_n_m"]]) if notes else math.nan,
        )


@dataclass(frozen=True)
class TrialOutcome:
    """How a trial run from the app ended."""

    code: str
    trial_ids: list[int]
    """The completed trial (empty when stopped or nothing was left to do)."""
    interrupted: int
    """Trials marked interrupted because the run was stopped."""
    wall_s: float


class TrialRun:
    """One trial of one participant, run by `run()` in a worker thread."""

    def __init__(
        self,
        engine,
        estimator,
        code: str,
        driver_kind: str,
        pace: float | None,
        keyboard: TuiKeyboardDriver | None = None,
    ) -> None:
        self.engine, self.estimator = engine, estimator
        self.code, self.driver_kind, self.pace = code, driver_kind, pace
        self.keyboard = keyboard
        self.live = LiveState()
        self._stop = threading.Event()
        self.finished = threading.Event()
        self.participant_id: int | None = None

    def stop(self) -> None:
        """Ask the trial to stop at its next batch of samples."""
        self._stop.set()

    def _on_samples(self, samples: np.ndarray) -> None:
        self.live.push(samples)
        if self._stop.is_set():
            raise TrialStopped

    def run(self, on_start: Callable[[object], None] = lambda _: None) -> TrialOutcome:
        """Run the participant's next trial; returns when it ends or is stopped."""
        from study.protocol.session import recover_interrupted, run_session

        start = time.monotonic()
        if self._stop.is_set():
            return TrialOutcome(self.code, [], 0, 0.0)

        def started(item, _k: int, _n: int) -> None:
            self.participant_id = item.block.participant_id
            on_start(item)

        keyboard = self.keyboard
        try:
            ids = run_session(
                self.engine,
                self.code,
                self.driver_kind,
                self.estimator,
                make_driver=(lambda: keyboard) if keyboard is not None else None,
                pace=self.pace,
                on_trial=started,
                max_trials=1,
                on_samples=self._on_samples,
            )
            return TrialOutcome(self.code, ids, 0, time.monotonic() - start)
        except TrialStopped:
            n = 0
            if self.participant_id is not None:
                n = recover_interrupted(self.engine, self.participant_id, STOPPED_REASON)
            return TrialOutcome(self.code, [], n, time.monotonic() - start)
        finally:
            self.finished.set()
