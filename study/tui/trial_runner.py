"""One trial from the terminal: the session runner in a worker thread, watched and stoppable.

The trial itself is `study.protocol.session.run_session` with `max_trials=1`: the same
`running` row, the same 1 s committed sample chunks, the same summary as `study run`.
This module adds what a terminal needs around it:

- `LiveState`: the newest samples, written by the worker (the session's observer,
  `_TrialWatch`) and read by the
  live view's timer; a lock guards the hand-over, so the UI never waits on the trial.
- holding: `TrialRun.hold()` makes the trial stand at its next step
  (`study.protocol.session.TrialHold`: its samples so far committed, its clock
  standing) while the operator is asked why it is stopped; `resume()` lets it go on.
- stopping: `TrialRun.stop()` sets an event (and lets a held trial go on to see it);
  the trial's next step, or its next batch of samples (50 ms of trial time when
  paced), raises `TrialStopped` inside the runner, the sample writer commits what it
  holds, and the trial is marked `interrupted` with `recover_interrupted` (an audit
  entry says why). Closing the app mid-trial goes the same way.
- `TuiKeyboardDriver`: `teleop_core`'s `KeyboardDriver`, ending the trial when the tip
  reaches the target (a person at the keys sees it on the screen). It drives NOTES
  blocks too: the NOTES loop reads the same `Driver` (the dial's aim sets the scope's
  insertion speed, the rotation keys its roll).

What the live view shows of a trial (its columns, traces and peaks) the trial's task
says (`study.protocol.tasks`): the runner hands the task to `LiveState` when the trial
starts.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from study.protocol.observer import Observers, SessionObserver, TrialInfo
from study.protocol.tasks import LiveTrace, Task, get_task
from study.tui.task_views import live_view
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
                from study.protocol.tasks import tasks
                from teleop_core.loop.drivers import SimulatedOperator

                estimator = self._load()
                for task in tasks():  # the tasks with a dial share the compiled loop
                    if task.has_dial:
                        loop = task.make_loop(
                            "HV", 0, estimator=estimator, context=task.session_context()
                        )
                        loop.start(SimulatedOperator())
                        loop.advance(0.05)
                        break
                self.estimator = estimator
            return self.estimator

    def prepare_in_background(
        self, done: Callable[[], None], failed: Callable[[BaseException], None]
    ) -> None:
        """`ready()` in a daemon thread, then `done()` or `failed(error)`. Quitting the app
        does not wait for it (it only loads and compiles; the loop's kernel cache is
        written to a temporary file and renamed, so an exit halfway leaves none)."""

        def run() -> None:
            try:
                self.ready()
            except Exception as exc:
                _if_app_alive(failed, exc)
                return
            _if_app_alive(done)

        threading.Thread(target=run, name="prepare-simulation", daemon=True).start()


def _if_app_alive(callback: Callable[..., None], *args: object) -> None:
    try:
        callback(*args)
    except RuntimeError:  # the app has ended meanwhile: nobody to tell
        pass


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
    """What the live view draws at one redraw: the newest sample by the task's column
    names (`values`), and the history of the task's two live traces (`live_traces`).

    The properties read the columns every task's rows start with (`pose_columns`, by
    their place) and its region: where the tip is, how far in, its roll."""

    task: Task
    values: dict[str, float]
    first_history: tuple[float, ...]
    second_history: tuple[float, ...]
    condition: str | None = None
    """The trial's condition (VO renders no force on the hand), if known."""

    def _pose(self, k: int) -> float:
        """The newest value of pose column `k` (`pose_columns`' order)."""
        return self.values[self.task.sample_columns[k].name]

    @property
    def t_s(self) -> float:
        return self._pose(0)

    @property
    def branch(self) -> int:
        return int(self.values[self.task.region_column])

    @property
    def insertion_m(self) -> float:
        return self._pose(1)

    @property
    def rotation_rad(self) -> float:
        return self._pose(2)

    @property
    def tip_xz_m(self) -> tuple[float, float]:
        return (self._pose(3), self._pose(5))

    def trace(self, k: int) -> float:
        """The newest value of live trace `k` (0 or 1), as its gauge shows it."""
        trace = live_view(self.task).traces[k]
        value = self.values[trace.column]
        return abs(value) if trace.magnitude else value


class LiveState:
    """The newest samples of the running trial, handed from the worker to the view."""

    def __init__(self, rate_hz: float = 100.0) -> None:
        self.task: Task | None = None
        """The running trial's task, set by `start` before its first samples."""
        self.condition: str | None = None
        """The running trial's condition, set by `start`."""
        self._lock = threading.Lock()
        self._last: np.ndarray | None = None
        self._index: dict[str, int] = {}
        n = round(HISTORY_S * rate_hz)
        self._first: deque[float] = deque(maxlen=n)
        self._second: deque[float] = deque(maxlen=n)
        self.batches = 0
        self.storage_wait: tuple[float, int] | None = None
        """(seconds waited, samples held) while another program holds the database's lock."""
        self.peaks = [0.0, 0.0]
        """The largest values of the task's two `live_peaks` so far."""

    def start(self, task: Task, condition: str | None = None) -> None:
        """A trial of `task` in `condition` begins (in the worker, before its samples)."""
        with self._lock:
            self.task, self.condition = task, condition
            self._index = task.column_index()
            self._last = None
            self._first.clear()
            self._second.clear()
            self.peaks = [0.0, 0.0]

    def _column(self, samples: np.ndarray, trace: LiveTrace) -> np.ndarray:
        values = samples[:, self._index[trace.column]]
        return np.abs(values) if trace.magnitude else values

    def push(self, samples: np.ndarray) -> None:
        """Take a batch of samples (in the worker)."""
        task = self.task
        if task is None:
            raise RuntimeError("LiveState.push before start(task)")
        view = live_view(task)
        first, second = (self._column(samples, t) for t in view.traces)
        peaks = [float(self._column(samples, t).max()) for t in view.shown_peaks]
        with self._lock:
            self._last = samples[-1].copy()
            self._first.extend(first.tolist())
            self._second.extend(second.tolist())
            self.batches += 1
            self.peaks = [max(a, b) for a, b in zip(self.peaks, peaks, strict=True)]

    def frame(self) -> LiveFrame | None:
        with self._lock:
            row, task, condition = self._last, self.task, self.condition
            if row is None or task is None:
                return None
            first, second = tuple(self._first), tuple(self._second)
        values = {c.name: float(row[k]) for k, c in enumerate(task.sample_columns)}
        return LiveFrame(task, values, first, second, condition)


class _TrialWatch(SessionObserver):
    """The session's events a terminal trial shows: the live view started with the
    trial's task, each batch of samples on it, a wait for another program's lock as its
    notice; a stop asked for (`TrialRun.stop`) raises `TrialStopped` at the next batch."""

    def __init__(self, run: TrialRun, on_start: Callable[[object], None]) -> None:
        self.run, self.on_start = run, on_start

    def trial_progress(self, pending, k: int, n: int) -> None:
        self.run.participant_id = pending.block.participant_id
        self.run.live.start(get_task(pending.block.task), pending.block.condition)
        self.on_start(pending)

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        if not len(rows):
            return
        self.run.live.push(rows)
        if self.run.stop_requested:
            raise TrialStopped

    def storage_wait(self, waited_s: float | None, held: int) -> None:
        self.run.live.storage_wait = None if waited_s is None else (waited_s, held)


@dataclass(frozen=True)
class TrialOutcome:
    """How a trial run from the app ended."""

    code: str
    trial_ids: list[int]
    """The completed trial (empty when stopped or nothing was left to do)."""
    interrupted: int
    """Trials marked interrupted because the run was stopped."""
    wall_s: float
    error: str = ""
    """Why the trial failed (its row stays `running` until the next start marks it
    interrupted), or empty."""


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
        observer=None,
    ) -> None:
        self.engine, self.estimator = engine, estimator
        self.observer = observer
        """The app's session observer (`StudyServices.lsl_observer`), if any."""
        self.code, self.driver_kind, self.pace = code, driver_kind, pace
        self.keyboard = keyboard
        self.live = LiveState()
        self._stop = threading.Event()
        self.finished = threading.Event()
        self.participant_id: int | None = None
        self.probe_line: str | None = None
        """What the probe step did before the trial (`study.tui.probe_step`), if anything."""
        self.stop_reason = STOPPED_REASON
        """Why the trial was stopped, for the audit log (`stop`)."""
        from study.protocol.session_settings import TrialHold  # loaded with the runner, when run

        self.holder = TrialHold(self._released)

    def hold(self) -> None:
        """Make the trial stand at its next step (samples so far committed, its clock
        standing) until `resume` or `stop`."""
        self.holder.hold()

    def resume(self) -> None:
        """Let a held trial go on where it stood."""
        self.holder.release()

    @property
    def held(self) -> bool:
        return self.holder.held

    def stop(self, reason: str | None = None) -> None:
        """Ask the trial to stop at its next step; `reason` (the operator's) goes into
        the audit row that marks it interrupted."""
        if reason:
            self.stop_reason = f"{STOPPED_REASON}: {reason}"
        self._stop.set()
        self.holder.release()

    @property
    def stop_requested(self) -> bool:
        return self._stop.is_set()

    def _released(self) -> None:
        if self._stop.is_set():
            raise TrialStopped

    def run(self, on_start: Callable[[object], None] = lambda _: None) -> TrialOutcome:
        """Run the participant's next trial; returns when it ends or is stopped."""
        # lazy: study.protocol.session (with pandas, pyarrow, numpy) costs 0.4 s at start-up
        from study.protocol.roster import read_design
        from study.protocol.session import recover_interrupted, run_session
        from study.protocol.session_settings import SessionSettings

        start = time.monotonic()
        if self._stop.is_set():
            return TrialOutcome(self.code, [], 0, 0.0)

        keyboard = self.keyboard
        # the session flow: the probes the design names before this block, then the block
        from study.tui.probe_step import run_due_probes

        design = read_design(self.engine)  # once: the probe step's and the session's
        self.probe_line = run_due_probes(
            self.engine, self.code, self.driver_kind, self.observer, design
        )
        try:
            settings = SessionSettings(
                self.driver_kind,
                self.estimator,
                make_driver=(lambda: keyboard) if keyboard is not None else None,
                pace=self.pace,
                max_trials=1,
                hold=self.holder,
                design=design,
                wait_out_storage=True,
            )
            watch = _TrialWatch(self, on_start)
            observer = Observers([watch, self.observer]) if self.observer else watch
            ids = run_session(self.engine, self.code, settings, observer)
            return TrialOutcome(self.code, ids, 0, time.monotonic() - start)
        except TrialStopped:
            n = 0
            if self.participant_id is not None:
                n = recover_interrupted(self.engine, self.participant_id, self.stop_reason)
            return TrialOutcome(self.code, [], n, time.monotonic() - start)
        finally:
            self.finished.set()
