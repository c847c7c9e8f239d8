"""Another program's lock during a trial: the trial goes on, the wait is on the screen,
and every sample is committed when the lock is gone."""

from __future__ import annotations

import time

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from db.models.trial import SampleChunk, Trial
from study.protocol.default_estimator import load_estimator
from study.tui.confirm import Confirm
from tests.db.test_samples_lock import Locker
from tests.study.tui.conftest import run_screen, wait_for


async def test_a_lock_during_a_trial_is_waited_out_and_loses_nothing(
    make_test_app, study_engine
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=2.0)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        await pilot.press("s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 20, 120)
        locker = Locker(study_engine.url.database)
        try:
            readout = app.query_one("#readout")
            await wait_for(pilot, lambda: "waiting for the database" in str(readout.render()), 30)
            moving = pane.run.live.batches
            await pilot.pause(1.0)
            assert pane.run is None or pane.run.live.batches > moving  # the view goes on
        finally:
            locker.release()
        await wait_for(pilot, lambda: pane.run is None, 120)
        assert pane.status == "completed", pane.last_outcome
    with Session(study_engine) as session:
        trial = session.scalars(select(Trial)).one()
        n = session.scalar(select(func.coalesce(func.sum(SampleChunk.n_samples), 0)))
    assert trial.status == "completed"
    assert n == round(trial.completion_time_s * 100)  # 100 Hz, from t = 0: none missing


async def test_a_60_s_lock_over_the_end_of_a_fast_trial_is_waited_out(
    make_test_app, study_engine
) -> None:
    # pace 8: the trial (some 20-40 s of trial time) ends while the lock is held, so
    # its last samples and its `completed` row wait for the lock's end; the busy
    # timeout (30 s by default) is shorter than the lock
    lock_s = 60.0
    app = make_test_app(load_estimator=load_estimator, simulated_pace=8.0)
    seen: set[str] = set()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        await pilot.press("s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 10, 120)
        locker = Locker(study_engine.url.database)
        locked_at = time.monotonic()
        try:
            readout = app.query_one("#readout")
            while time.monotonic() - locked_at < lock_s:
                seen.add(pane.status)
                if "waiting for the database" in str(readout.render()):
                    seen.add("wait shown")
                await pilot.pause(0.2)
            held = pane.run.live.storage_wait if pane.run is not None else None
        finally:
            locker.release()
        await wait_for(pilot, lambda: pane.run is None, 120)
        assert pane.status == "completed", pane.last_outcome
    assert "wait shown" in seen
    assert seen <= {"running", "wait shown"}, seen  # never idle, failed or stopped
    assert held is not None
    assert held[0] > lock_s - 5
    with Session(study_engine) as session:
        trial = session.scalars(select(Trial)).one()
        n = session.scalar(select(func.coalesce(func.sum(SampleChunk.n_samples), 0)))
    assert trial.status == "completed"
    assert n == round(trial.completion_time_s * 100)  # 100 Hz, from t = 0: none missing
