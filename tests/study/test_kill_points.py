"""Twenty `kill -9` at seeded random points.

The target: "20 kill -9 at random points, including the parent of --jobs 2: 0 completed trials
lost, <= 1.0 s of samples lost, 0 slots completed twice."

- Four chains of four kills of a session, each at a random trial time: the
  process kills itself (SIGKILL) at the first step at or after that time, so the point
  is exact whatever the load, and the next session of the chain is the recovery of the
  last. After each kill: every trial the session had finished is `completed` with all
  its samples, the killed trial kept its samples up to at most 1.0 s before the kill,
  and no slot is completed twice.
- One chain of four kills of the parent of `--jobs 2`, each once the workers have a
  random amount of trial time stored: the workers end (marking their trials
  interrupted), nothing is written afterwards, completed trials are whole and no slot
  is completed twice; the next parent recovers and continues.

Everything is asserted on what the database holds, not on timing. The kill points come
from `numpy.random.default_rng(chain)`; the processes are forks of one server that
imported the session code once (`kill_children`), to keep the twenty cases short.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.engine import make_engine
from db.models.study import Participant
from db.models.trial import Trial
from study.cli import main
from tests.study import kill_children
from tests.study.conftest import assert_workers_end, last_sample_s, samples_of_trial

DESIGN = """\
name = "kill points"
seed = 3
trials_per_condition = 3
practice_trials = 0
[groups]
novice = 2
"""
KILLS_PER_CHAIN = 4


@pytest.fixture(scope="module")
def server() -> multiprocessing.context.BaseContext:
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(kill_children.PRELOAD)
    return context


def _study(tmp_path: Path) -> str:
    db = tmp_path / "s.db"
    (tmp_path / "d.toml").write_text(DESIGN)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", str(db)]) == 0
    assert main(["participant", "add", "--group", "novice", "--count", "2", "--db", str(db)]) == 0
    return f"sqlite:///{db}"


def _trials(url: str) -> dict[int, dict]:
    """Every trial: slot, status, samples stored, the latest sample time, the summary."""
    engine = make_engine(url)
    with Session(engine) as s:
        rows = s.execute(
            select(
                Trial.id,
                Participant.code,
                Trial.block_index,
                Trial.trial_index,
                Trial.status,
                Trial.summary,
                samples_of_trial(),
                last_sample_s(Trial.id).scalar_subquery(),
            )
            .join(Participant, Trial.participant_id == Participant.id)
            .order_by(Trial.id)
        ).all()
    engine.dispose()
    return {
        r[0]: {"slot": r[1:4], "status": r[4], "summary": r[5], "samples": r[6], "last_s": r[7]}
        for r in rows
    }


def _check_invariants(trials: dict[int, dict], before: dict[int, dict]) -> None:
    """Completed trials whole and unchanged, no slot completed twice."""
    completed = [t for t in trials.values() if t["status"] == "completed"]
    for t in completed:
        assert t["samples"] == t["summary"]["samples"] > 0, t
    slots = [t["slot"] for t in completed]
    assert len(slots) == len(set(slots)), f"a slot completed twice: {sorted(slots)}"
    for trial_id, t in before.items():
        if t["status"] == "completed":
            assert trials[trial_id] == t, "a completed trial changed"


def _run(  # type: ignore[no-untyped-def]
    server: multiprocessing.context.BaseContext, target, *args
) -> int:
    process = server.Process(target=target, args=args)
    process.start()
    process.join(timeout=240)
    if process.is_alive():
        process.kill()
        pytest.fail(f"{target.__name__}{args} did not end")
    return process.exitcode


@pytest.mark.parametrize("chain", [0, 1, 2, 3])
def test_a_session_killed_at_random_points_loses_no_trial_and_at_most_one_second(
    chain: int, tmp_path: Path, server: multiprocessing.context.BaseContext
) -> None:
    url = _study(tmp_path)
    rng = np.random.default_rng(chain)
    code = f"P00{chain % 2 + 1}"
    for k in range(KILLS_PER_CHAIN):
        # one kill of each chain after a trial of its own completed (a full trial is the
        # expensive part), the others in the first trial the session runs
        after_trials = int(k == chain)
        die_at_s = round(float(rng.uniform(0.3, 8.0)), 2)
        before = _trials(url)
        log = tmp_path / f"kill{k}.log"
        rc = _run(
            server, kill_children.session_killed_at, url, code, after_trials, die_at_s, str(log)
        )
        lines = log.read_text().split()
        assert rc == -signal.SIGKILL, rc  # 6 trials a participant: never run out first
        killed_at_s = float(lines[-1])
        after = _trials(url)
        _check_invariants(after, before)
        new = {i: t for i, t in after.items() if i not in before}
        # every trial whose successor started was completed: none of them lost
        n_finished = lines.count("start") - 1
        assert sum(t["status"] == "completed" for t in new.values()) == n_finished
        running = [t for t in after.values() if t["status"] == "running"]
        assert len(running) == 1
        assert running[0] in new.values()
        kept_s = running[0]["last_s"] if running[0]["samples"] else 0.0
        assert killed_at_s - kept_s <= 1.0 + 0.011, (killed_at_s, kept_s)  # one 100 Hz step
    final = _trials(url)
    _check_invariants(final, {})


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="finds the workers through /proc")
def test_the_parent_of_jobs_2_killed_at_random_points_loses_nothing_completed(
    tmp_path: Path, server: multiprocessing.context.BaseContext
) -> None:
    url = _study(tmp_path)
    rng = np.random.default_rng(18)
    for _ in range(KILLS_PER_CHAIN):
        threshold = int(rng.integers(50, 800))  # samples of stored trial time (100 Hz)
        before = _trials(url)
        parent = server.Process(target=kill_children.run_all_jobs_2, args=(url, ["P001", "P002"]))
        parent.start()
        try:
            deadline = time.monotonic() + 180
            while time.monotonic() < deadline:
                time.sleep(0.1)
                now = _trials(url)
                fresh = [t for i, t in now.items() if i not in before and t["status"] == "running"]
                if any(t["samples"] >= threshold for t in fresh) or not parent.is_alive():
                    break
            workers = kill_children.worker_pids(parent.pid)
            assert parent.is_alive(), "the kill point was never reached"
            assert len(workers) == 2, "the kill point was never reached"
            seen = _trials(url)  # what the database held at the kill
            os.kill(parent.pid, signal.SIGKILL)
            parent.join(timeout=10)
        finally:
            if parent.is_alive():
                parent.kill()
        assert_workers_end(workers, 60)
        stopped = _trials(url)
        _check_invariants(stopped, before)
        # samples lost: none of those stored at the kill (the workers were not killed;
        # what they had not yet committed when they stopped is bounded by the writer's
        # one-second rule, which the session kills above measure)
        assert all(stopped[i]["samples"] >= t["samples"] for i, t in seen.items())
        assert not [t for t in stopped.values() if t["status"] == "running"]
        # killed mid-trial: the workers marked what they were running interrupted
        assert any(t["status"] == "interrupted" for i, t in stopped.items() if i not in before)
        time.sleep(0.5)
        assert _trials(url) == stopped  # nothing is written after the workers ended
    _check_invariants(_trials(url), {})
