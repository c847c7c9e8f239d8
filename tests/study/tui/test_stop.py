"""The run screen's stop: `x` holds the trial at once while its reason is asked, a reason
stores it interrupted (the reason audited), Esc lets it go on, an empty reason is
answered, and a trial that ended first is offered for invalidation."""

from __future__ import annotations

import time

from sqlalchemy import select
from sqlalchemy.orm import Session
from textual.widgets import Label

from db.models.audit import AuditEntry
from db.models.trial import Trial
from study.protocol.default_estimator import load_estimator
from study.tui.stop_dialog import StopScreen
from study.tui.trial_runner import STOPPED_REASON
from tests.study.conftest import stored_samples
from tests.study.tui.conftest import wait_for
from tests.study.tui.test_run_session import _start


def _stored(engine) -> list[tuple[str, int, str | None]]:
    """(status, samples stored, invalid reason) of every trial."""
    with Session(engine) as session:
        rows = session.execute(select(Trial.id, Trial.status, Trial.invalid_reason)).all()
        return [(s, session.scalar(stored_samples(tid)), why) for tid, s, why in rows]


def _trial_audit(engine) -> list[tuple[str, str | None, str | None, str | None]]:
    with Session(engine) as session:
        rows = session.scalars(select(AuditEntry).where(AuditEntry.entity == "trial")).all()
        return [(e.field, e.old_value, e.new_value, e.reason) for e in rows]


def _dialog_text(app) -> str:
    return " ".join(str(label.render()) for label in app.screen.query(Label))


async def test_x_holds_the_trial_while_a_slow_reason_is_typed_and_the_reason_stops_it(
    make_test_app, study_engine
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=1.0)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _start(pilot, "P002", "d")  # the keyboard: the trial runs on until stopped
        await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 10, 120)
        run = pane.run
        await pilot.press("x")
        await wait_for(pilot, lambda: isinstance(app.screen, StopScreen), 10)
        await wait_for(pilot, lambda: run.holder.standing.is_set(), 10)
        batches, t_s = run.live.batches, run.live.frame().t_s
        [(status, committed, _)] = _stored(study_engine)
        # standing, the samples measured so far are all committed (a crash loses none)
        assert status == "running"
        assert committed == round(t_s * 100)
        time.sleep(2.5)  # the operator thinks, then types slowly: 5 s in all
        await pilot.press(*"dial")
        time.sleep(2.5)
        await pilot.press(*" slipped")
        assert run.live.batches == batches  # nothing ran while the reason was typed
        assert _stored(study_engine) == [("running", committed, None)]
        assert pane.status == "held"
        await pilot.press("enter")
        await wait_for(pilot, lambda: pane.status == "interrupted", 30)
    # every sample measured before x is kept, none after it
    assert _stored(study_engine) == [("interrupted", committed, None)]
    assert _trial_audit(study_engine) == [
        ("status", "running", "interrupted", f"{STOPPED_REASON}: dial slipped")
    ]


async def test_an_empty_reason_is_answered_and_esc_lets_the_trial_go_on_to_its_end(
    make_test_app, study_engine
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=4.0)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _start(pilot, "P001")
        await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 5, 120)
        run = pane.run
        await pilot.press("x")
        await wait_for(pilot, lambda: run.holder.standing.is_set(), 10)
        await pilot.press("enter")  # no reason: said so, the dialog stays, the trial stands
        await pilot.pause()
        assert isinstance(app.screen, StopScreen)
        assert "a reason is needed to stop it" in _dialog_text(app)
        assert run.held
        t_s = run.live.frame().t_s
        await pilot.press("escape")
        await wait_for(pilot, lambda: pane.status == "completed", 120)
        assert run.live.frame().t_s > t_s  # it went on from where it stood
    [(status, samples, invalid)] = _stored(study_engine)
    assert (status, invalid) == ("completed", None)
    with Session(study_engine) as session:
        trial = session.scalars(select(Trial)).one()
    # the held time is not trial time: one sample per 10 ms of the trial, as unheld
    assert samples == round(trial.completion_time_s * 100) == trial.summary["samples"]
    assert _trial_audit(study_engine) == []


async def test_a_trial_that_ended_before_the_answer_is_offered_for_invalidation(
    make_test_app, study_engine
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=4.0)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _start(pilot, "P001")
        await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 0, 120)
        run = pane.run
        # x comes as the trial's thread is past its last step: the screen has not yet
        # heard that it ended (the event loop is kept busy until it has)
        assert run.finished.wait(60)
        pane.action_stop()
        await wait_for(pilot, lambda: pane.status == "completed", 30)
        await wait_for(pilot, lambda: "Invalidate it instead?" in _dialog_text(app), 10)
        assert "ended before it was stopped: it is stored as completed" in _dialog_text(app)
        await pilot.press("enter")
        await pilot.pause()
        assert "a reason is needed to invalidate it" in _dialog_text(app)
        await pilot.press(*"cable loose", "enter")
        await wait_for(pilot, lambda: _stored(study_engine)[0][2] is not None, 10)
    [(status, _, invalid)] = _stored(study_engine)
    assert (status, invalid) == ("completed", "cable loose")


async def test_the_app_ending_under_the_dialog_stops_the_held_trial(
    make_test_app, study_engine
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=1.0)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _start(pilot, "P002", "d")
        await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 2, 120)
        run = pane.run
        await pilot.press("x")
        await wait_for(pilot, lambda: run.holder.standing.is_set(), 10)
        app.exit()  # not through ctrl+q (a signal, an error): nothing answers the dialog
    assert run.finished.wait(30)
    [(status, samples, _)] = _stored(study_engine)
    assert status == "interrupted"
    assert samples > 0
