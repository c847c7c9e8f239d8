"""`x` on a running trial: held at once while the reason is typed, stopped with it, let go
on with Esc; a trial that ended before the hold reached it is offered for invalidation."""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session
from textual.widgets import Label

from db.migrate import open_database
from db.models.audit import AuditEntry
from db.models.trial import Trial
from study.protocol.default_estimator import load_estimator
from study.protocol.design import parse_design
from study.protocol.roster import add_participant, create_study
from study.protocol.session import run_session
from study.tui.confirm import Confirm
from study.tui.run_pane import RunPane
from study.tui.stop_dialog import StopTrial
from study.tui.trial_runner import STOPPED_REASON, TrialRun
from tests.study.conftest import stored_samples
from tests.study.tui.conftest import DESIGN, run_screen, wait_for

PACE = 20.0
"""Times real time: a simulated trial of some 30 s lasts about 1.5 s."""


async def _running(pilot, code: str) -> RunPane:
    """`code`'s next trial started (checklist confirmed) and a few batches in."""
    pane = await run_screen(pilot, code)
    await pilot.press("s")
    await wait_for(pilot, lambda: isinstance(pilot.app.screen, Confirm), 10)
    await pilot.press("y")
    await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 2, 120)
    return pane


def _trial(engine) -> tuple[str, int, float | None, str | None]:
    """(status, samples stored, completion time, invalid reason) of the only trial."""
    with Session(engine) as session:
        t = session.scalars(select(Trial)).one()
        return (
            t.status,
            session.scalar(stored_samples(t.id)),
            t.completion_time_s,
            t.invalid_reason,
        )


async def test_x_holds_the_trial_at_once_and_a_reason_typed_slowly_stops_it(
    make_test_app, study_engine
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=PACE)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _running(pilot, "P001")
        run = pane.run
        await pilot.press("x")
        assert isinstance(app.screen, StopTrial)
        await wait_for(pilot, run.holder.waiting.is_set, 10)  # the loop waits
        held_at = run.live.frame().t_s
        batches = run.live.batches
        # longer than the whole trial takes at this pace: it does not go on meanwhile
        await pilot.pause(2.0)
        assert run.live.batches == batches
        assert run.live.frame().t_s == held_at
        status, samples, _, _ = _trial(study_engine)
        assert status == "running"
        assert samples == round(held_at * 100)  # what it measured so far is stored
        # Enter with no reason says what is needed, and stops nothing
        await pilot.press("enter")
        needed = str(app.screen.query_one("#stop-needed", Label).render())
        assert needed.startswith("a reason is needed")
        assert run.held
        for key in "cable snagged":  # typed slowly
            await pilot.press("space" if key == " " else key)
            await pilot.pause(0.05)
        await pilot.press("enter")
        await wait_for(pilot, lambda: pane.status == "interrupted", 30)
    status, samples, _, _ = _trial(study_engine)
    assert status == "interrupted"
    assert samples == round(held_at * 100)  # none taken after the hold
    with Session(study_engine) as session:
        entry = session.scalars(select(AuditEntry).where(AuditEntry.entity == "trial")).one()
    assert (entry.old_value, entry.new_value) == ("running", "interrupted")
    assert entry.reason == f"{STOPPED_REASON}: cable snagged"


def _unheld_completion_time(tmp_path: Path) -> float:
    """The same participant's first trial run by `study run`'s runner, never held."""
    engine = open_database(str(tmp_path / "unheld.db"), create=True)
    try:
        create_study(engine, parse_design(DESIGN), DESIGN)
        add_participant(engine, "novice")
        add_participant(engine, "expert")
        run_session(engine, "P001", "simulated", load_estimator(), max_trials=1, pace=PACE)
        return _trial(engine)[2]
    finally:
        engine.dispose()


async def test_esc_lets_the_held_trial_go_on_and_the_held_time_is_not_trial_time(
    make_test_app, study_engine, tmp_path: Path
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=PACE)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _running(pilot, "P001")
        run = pane.run
        await pilot.press("x")
        await wait_for(pilot, run.holder.waiting.is_set, 10)
        assert pane.status == "held"
        await pilot.pause(1.0)  # 20 s of trial time at this pace, were it counted
        await pilot.press("escape")
        assert not isinstance(app.screen, StopTrial)
        await wait_for(pilot, lambda: pane.status == "completed", 60)
    status, samples, completion_s, _ = _trial(study_engine)
    assert status == "completed"
    # the trial's clock stood while held: the same trial unheld (same seed) takes as long
    assert completion_s == _unheld_completion_time(tmp_path)
    assert samples == round(completion_s * 100)


async def test_a_trial_that_ends_before_the_hold_is_offered_for_invalidation(
    make_test_app, study_engine, monkeypatch
) -> None:
    monkeypatch.setattr(TrialRun, "hold", lambda self: None)  # the hold comes too late
    app = make_test_app(load_estimator=load_estimator, simulated_pace=PACE)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _running(pilot, "P001")
        await pilot.press("x")
        dialog = app.screen
        assert isinstance(dialog, StopTrial)
        await wait_for(pilot, lambda: dialog.mode == "invalidate", 60)
        question = str(dialog.query_one("#question", Label).render())
        assert "ended before it could be stopped" in question
        assert "Mark it invalid instead?" in question
        assert pane.status == "completed"
        await pilot.press(*"dial slipped", "enter")
        await wait_for(pilot, lambda: _trial(study_engine)[3] is not None, 30)
    status, _, _, invalid = _trial(study_engine)
    assert (status, invalid) == ("completed", "dial slipped")
