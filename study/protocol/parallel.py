"""Sessions of many participants at once: `study run --all --jobs N`, `study demo`.

Each worker process opens its own connection, loads the estimator once and runs whole
sessions (`study.protocol.session.run_session`) one participant at a time; a worker
ends when its parent dies (it watches the parent's pid), marking its running trial
interrupted first.

`start_workers` starts the processes before their database need exist (each opens it
at its first session), so that their start (an interpreter each, and the imports of a
session) runs beside the caller's own start; `Workers.run` runs the sessions and
`Workers.submit` hands them other work once the sessions are done (`study demo`'s
second set of figures).
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from types import TracebackType
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from study.protocol.design import StudyDesign

T = TypeVar("T")
_WORKER: dict[str, object] = {}
PARENT_POLL_S = 0.5
"""How often a `--jobs` worker checks that its parent is alive."""
STOP_GRACE_S = 10.0
"""How long a worker whose parent died may take to mark its trial and leave."""


def watch_parent(
    parent_pid: int, stop: threading.Event | None = None, idle: threading.Event | None = None
) -> None:
    """End this worker process when its parent dies, from a thread started here: else,
    after `kill -9` of `study run --all --jobs 2`, the workers would keep running and
    writing, and a pool's idle workers would wait on its task queue for good (they share
    its pipe, so none reads an end of file). With `stop` and `idle`: `stop` is set and
    the worker's session (which stops at its next step and marks its trial interrupted)
    gets until `idle` is set, at most `STOP_GRACE_S`; a worker stuck longer exits hard,
    which leaves a lease of a gone process that the next run takes over at once."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        if stop is not None and idle is not None:
            stop.set()
            idle.wait(STOP_GRACE_S)
        os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _worker_init(
    db_url: str | None,
    parent_pid: int | None = None,
    actor: str | None = None,
    participants: str | None = None,
    durable: bool = True,
) -> None:
    # lazy: study.protocol.default_estimator (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.protocol.default_estimator import load_estimator

    # lazy: study.protocol.participant_model (with numpy) costs 0.1 s at start-up
    from study.protocol.participant_model import load_model

    importlib.import_module("study.protocol.session")  # here, not at the first session
    old = _WORKER.pop("engine", None)  # one job: this process's earlier database
    if old is not None:
        old.dispose()  # type: ignore[attr-defined]
    _WORKER["db_url"], _WORKER["durable"] = db_url, durable
    _WORKER["estimator"] = load_estimator()
    _WORKER["actor"] = actor
    _WORKER["participants"] = load_model(participants) if participants is not None else None
    stop, idle = threading.Event(), threading.Event()
    idle.set()
    _WORKER["stop"], _WORKER["idle"] = stop, idle
    if parent_pid is not None:
        watch_parent(parent_pid, stop, idle)


def _worker_engine() -> Any:
    """The worker's engine, opened at its first session (the database may not exist yet
    when the worker starts)."""
    if "engine" not in _WORKER:
        from db.migrate import open_database

        _WORKER["engine"] = open_database(
            _WORKER["db_url"],  # type: ignore[arg-type]
            create=False,
            durable=bool(_WORKER["durable"]),
        )
    return _WORKER["engine"]


def _worker_run(
    code: str, pace: float | None = None, design: StudyDesign | None = None
) -> tuple[str, int]:
    # lazy: study.protocol.session (with pandas, pyarrow, sqlalchemy) costs 0.8 s at start-up
    from study.protocol.session import run_session
    from study.protocol.session_settings import SessionSettings

    idle: threading.Event = _WORKER["idle"]  # type: ignore[assignment]
    idle.clear()
    try:
        settings = SessionSettings(
            "simulated",
            _WORKER["estimator"],  # type: ignore[arg-type]
            pace=pace,
            actor=_WORKER["actor"],  # type: ignore[arg-type]
            stop=_WORKER["stop"],  # type: ignore[arg-type]
            participants=_WORKER["participants"],  # type: ignore[arg-type]
            design=design,
        )
        done = run_session(_worker_engine(), code, settings)
    finally:
        idle.set()
    return code, len(done)


TRACKER_WARNING = "ignore:resource_tracker:UserWarning"


def quiet_resource_tracker() -> None:
    """Keep multiprocessing's resource tracker from warning about "leaked semaphore
    objects" when this process is killed: the tracker (started with this interpreter's
    -W options) unlinks the pool's semaphores then, which is its job after a crash, but
    its warning told the person who killed `study run` nothing they could act on. Set
    before the pool starts the tracker; the cleanup itself is unchanged."""

    if TRACKER_WARNING not in sys.warnoptions:
        sys.warnoptions.append(TRACKER_WARNING)


def compile_loop_once(notice: Callable[[str], None] | None = None) -> bool:
    """Where the loop's kernel is not compiled on this machine yet (the first run after
    install, or after an upgrade), say so through `notice` and compile it here, once,
    before any worker starts: the workers then load it instead of each compiling it at
    the same time. Returns whether it compiled."""
    # lazy: teleop_core.loop (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from teleop_core.loop import kernel

    # lazy: teleop_core.phantom.lcca (with numpy) costs 82 ms at start-up
    from teleop_core.phantom.lcca import lcca_phantom

    if not kernel.needs_compiling(lcca_phantom):
        return False
    if notice is not None:
        notice("compiling the simulation loop (once after install; later runs load it)")
    start = time.monotonic()
    kernel.kernel_for(lcca_phantom)
    if notice is not None:
        notice(f"compiled the simulation loop in {time.monotonic() - start:.0f} s")
    return True


def _started() -> None:
    """A worker's first task: returns once the worker has started (its initializer ran)."""


class Workers:
    """The processes of `start_workers`; use as a context manager (the processes end at
    its exit). With one job there is no process: the work runs in this one."""

    def __init__(
        self,
        db_url: str | None,
        jobs: int,
        actor: str | None = None,
        participants: str | None = None,
        durable: bool = True,
    ) -> None:
        self.jobs = jobs
        self._db_url = db_url
        self._pool: ProcessPoolExecutor | None = None
        if jobs == 1:
            _worker_init(db_url, actor=actor, participants=participants, durable=durable)
            return
        quiet_resource_tracker()
        context = multiprocessing.get_context("spawn")
        self._pool = ProcessPoolExecutor(
            jobs,
            mp_context=context,
            initializer=_worker_init,
            initargs=(db_url, os.getpid(), actor, participants, durable),
        )
        self._pool.submit(_started)  # the pool starts its processes at the first task

    def __enter__(self) -> Workers:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=exc is not None)
            if self._db_url is not None:
                _checkpoint(self._db_url)

    def run(
        self,
        codes: list[str],
        pace: float | None = None,
        on_busy: Callable[[str, str], None] | None = None,
        design: StudyDesign | None = None,
    ) -> Iterator[tuple[str, int]]:
        """Run the sessions of `codes`; yield (code, trials) as each finishes (see
        `run_participants`)."""
        # lazy: study.protocol.lease (with sqlalchemy) costs 0.3 s at start-up
        from study.protocol.lease import SessionBusyError

        def busy(code: str, exc: SessionBusyError) -> tuple[str, int]:
            if on_busy is None:
                raise exc
            on_busy(code, str(exc))
            return code, 0

        if self._pool is None:
            for code in codes:
                try:
                    yield _worker_run(code, pace, design)
                except SessionBusyError as exc:
                    yield busy(code, exc)
            return
        futures = {self._pool.submit(_worker_run, code, pace, design): code for code in codes}
        for future in as_completed(futures):
            try:
                yield future.result()
            except SessionBusyError as exc:
                yield busy(futures[future], exc)

    def submit(self, fn: Callable[..., T], *args: Any) -> Future[T]:
        """Run `fn(*args)` in a worker (a module-level function: it is sent by name); with
        one job, here and now."""
        if self._pool is not None:
            return self._pool.submit(fn, *args)
        done: Future[T] = Future()
        try:
            done.set_result(fn(*args))
        except Exception as exc:  # handed to the caller, as the pool does
            done.set_exception(exc)
        return done


def start_workers(
    db_url: str | None,
    jobs: int,
    actor: str | None = None,
    participants: str | None = None,
    notice: Callable[[str], None] | None = None,
    durable: bool = True,
) -> Workers:
    """Start `jobs` session workers for the database at `db_url`, which need not exist
    yet (a worker opens it at its first session). The loop's kernel is compiled first
    where it is not yet (`compile_loop_once`, told through `notice`). `participants`,
    `actor`, `durable`: as in `run_participants`."""
    compile_loop_once(notice)
    return Workers(db_url, jobs, actor, participants, durable)


def run_participants(
    db_url: str | None,
    codes: list[str],
    jobs: int,
    pace: float | None = None,
    actor: str | None = None,
    on_busy: Callable[[str, str], None] | None = None,
    participants: str | None = None,
    notice: Callable[[str], None] | None = None,
    durable: bool = True,
    design: StudyDesign | None = None,
) -> Iterator[tuple[str, int]]:
    """Run simulated sessions for `codes` in `jobs` processes; yield (code, trials) as each
    finishes. Each process opens its own connection and loads the estimator once, and
    ends when this process dies.

    A participant whose session runs elsewhere (`SessionBusyError`) is skipped and
    reported through `on_busy(code, message)` (raised when `on_busy` is None).
    `participants`: the path of a fitted participant model (MODEL.json) to draw from.
    `notice` is told when the loop's kernel is compiled first (`compile_loop_once`).
    `durable=False`: the workers' commits are not synced one by one
    (`db.engine.make_engine`), for a database thrown away when it is not finished.
    `design`: the study's design as the caller read it from the same database, handed to
    every session with its participant (each session reads it itself when None).
    """
    with start_workers(db_url, jobs, actor, participants, notice, durable) as workers:
        yield from workers.run(codes, pace, on_busy, design)


def _checkpoint(db_url: str) -> None:
    """The workers ended without closing their connections, which leaves an SQLite
    database's write-ahead log full: fold it into the database file
    (`db.engine.checkpoint`), so the file alone holds every trial. A database that
    cannot be opened now (never created, or gone) is left to the error that says so."""
    # lazy: sqlalchemy.exc costs 0.2 s at start-up
    from sqlalchemy.exc import OperationalError

    # lazy: db.engine (with sqlalchemy) costs 0.2 s at start-up
    from db.engine import checkpoint, make_engine, resolve_url

    engine = make_engine(resolve_url(db_url))
    try:
        checkpoint(engine)
    except OperationalError:
        pass
    finally:
        engine.dispose()
