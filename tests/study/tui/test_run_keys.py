"""The run screen's keys: p cycles any starting pace, e asks before ending a measured trial,
and the footer offers only the keys that act now."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session
from textual.widgets import Label

from db.models.trial import Trial
from study.protocol.default_estimator import load_estimator
from study.tui.confirm import Confirm
from tests.study.tui.conftest import run_screen, wait_for


def _footer_keys(app) -> set[str]:
    return {k.key for k in app.query("FooterKey")}


async def test_p_cycles_a_pace_given_on_the_command_line(make_test_app) -> None:
    app = make_test_app(simulated_pace=8.0)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        assert "pace: 8x (p)" in str(app.query_one("#mode", Label).render())
        seen = []
        for _ in range(4):
            await pilot.press("p")
            seen.append(pane.pace)
        # 8x, then the usual 1x, 4x, as fast as it goes, and back to 8x
        assert seen == [1.0, 4.0, None, 8.0]
        assert app.is_running


async def test_e_asks_before_ending_a_measured_trial(make_test_app, study_engine) -> None:
    app = make_test_app(load_estimator=load_estimator)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        await pilot.press("d")  # the keyboard drives: p (pace) is not offered for it
        await pilot.pause()
        assert "p" not in _footer_keys(app)
        assert "d" in _footer_keys(app)
        await pilot.press("s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")  # the session checklist
        await wait_for(pilot, lambda: pane.status == "running", 120)
        await pilot.pause()
        # during the trial neither start, driver nor pace is offered; stop is
        assert {"s", "d", "p"}.isdisjoint(_footer_keys(app))
        assert "x" in _footer_keys(app)
        await pilot.press("e")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        assert "measured trial" in str(app.screen.query_one("#question").render())
        await pilot.press("n")
        await pilot.pause(0.5)
        assert pane.run is not None
        assert pane.status == "running"
        await pilot.press("e")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: pane.run is None, 60)
        assert "x" not in _footer_keys(app)
    with Session(study_engine) as session:
        trial = session.scalars(select(Trial)).one()
    assert (trial.status, trial.success, trial.driver) == ("completed", False, "keyboard")


async def test_f3_focuses_the_participant_list_until_one_is_picked(make_test_app) -> None:
    """F3 with nobody picked: Enter opens the participant list at once (it used to do
    nothing until Tab); with a participant picked, the screen's own keys act."""
    from textual.widgets import Select

    from study.tui.picker import ParticipantPicker
    from study.tui.run_pane import RunPane
    from tests.study.tui.conftest import loaded

    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f3")
        await pilot.pause()
        picker = app.query_one("#participant", Select)
        assert app.focused is picker
        await pilot.press("enter")
        await pilot.pause()
        assert isinstance(app.screen, ParticipantPicker)
        await pilot.press("down", "enter")
        await pilot.pause()
        assert app.query_one(RunPane).code is not None
        await pilot.press("f1", "f3")
        await pilot.pause()
        assert app.focused is app.query_one(RunPane)
