"""Processes that `test_kill_points.py` kills with SIGKILL (not a test module).

They run in children of a multiprocessing fork server that imported the session code
once, so twenty kills cost twenty forks rather than twenty interpreter starts.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import types
from pathlib import Path

from study.protocol.session import participant_traits, run_session
from study.protocol.session_settings import SessionSettings
from study.tasks.lcca.simulated_participant import SimulatedParticipant

PRELOAD = [__name__, "tests.study.kill_warmup"]
"""What the fork server imports before it forks: this module and the compiled loop."""


def session_killed_at(url: str, code: str, after_trials: int, die_at_s: float, log: str) -> None:
    """Run `code`'s session; in its trial number `after_trials` (from 0) or a later one,
    SIGKILL this process at the first step at or after `die_at_s` of trial time.

    `log` gets a line `start` as each trial's driver is made (so every trial before it
    in this session was completed and committed) and `kill T` just before the kill."""
    from db.migrate import open_database
    from study.protocol.default_estimator import load_estimator
    from teleop_core.phantom.lcca import LccaPhantom

    engine = open_database(url, create=False)
    phantom = LccaPhantom()
    traits = participant_traits(3, code, "novice")
    started = []

    class DiesAt(SimulatedParticipant):
        def act(self, view):  # type: ignore[no-untyped-def]
            if len(started) > after_trials and view.t_s >= die_at_s:
                with open(log, "a") as f:
                    f.write(f"kill {view.t_s!r}\n")
                os.kill(os.getpid(), signal.SIGKILL)
            return super().act(view)

    def make_driver() -> DiesAt:
        started.append(1)
        with open(log, "a") as f:
            f.write("start\n")
        return DiesAt(traits, phantom, 180.0)

    settings = SessionSettings("simulated", load_estimator(), make_driver=make_driver)
    run_session(engine, code, settings)


PACE = 20.0
"""Times real time the sessions of `run_all_jobs_2` run at: a session then outlasts the
workers' check of their parent (`parallel.PARENT_POLL_S`, 0.5 s). Unpaced, a fast host
(about 500x real time) ran a participant's six trials in under 0.5 s, and
the kill met sessions already finished instead of a trial to interrupt."""


def run_all_jobs_2(url: str, codes: list[str]) -> None:
    """`study run --all --jobs 2 --pace 20` as its parent process runs it
    (`run_participants`), with the workers forked from this process instead of spawned
    (the same parent and parent-watch, without two interpreter starts per case)."""
    import study.protocol.parallel as session

    fork = multiprocessing.get_context("fork")
    shim = types.SimpleNamespace(get_context=lambda _method: fork)
    session.multiprocessing = shim  # type: ignore[assignment]
    for _ in session.run_participants(url, codes, jobs=2, pace=PACE):
        pass


def worker_pids(parent: int) -> list[int]:
    """Live children of `parent` (the `--jobs` workers), from /proc."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            fields = stat.rpartition(")")[2].split()
            if int(fields[1]) == parent and fields[0] != "Z":
                out.append(int(entry.name))
    return out
