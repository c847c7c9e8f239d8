"""The screens read the database again (once a second and on each screen switch): what
the command line changes while the app runs shows, and an enrolment past a target or a
start with nothing left is decided on what the database holds now."""

from __future__ import annotations

import time

from sqlalchemy import func, select
from sqlalchemy.orm import Session
from textual.widgets import DataTable, Label

from db.models.study import Participant
from db.models.trial import Trial
from study.protocol.default_estimator import load_estimator
from study.protocol.roster import add_participant
from study.protocol.session import run_session
from study.protocol.session_settings import SessionSettings
from study.tui.confirm import Confirm
from tests.study.tui.conftest import on_screen, run_screen, wait_for


def _codes(table: DataTable) -> list[str]:
    return [str(table.get_row_at(k)[0]) for k in range(table.row_count)]


async def test_a_participant_enrolled_from_the_command_line_shows_on_f2_within_2_s(
    make_test_app, study_engine
) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        table = app.query_one("#people", DataTable)
        assert _codes(table) == ["P001", "P002"]
        add_participant(study_engine, "novice")  # as `study participant add` does
        added = time.monotonic()
        await wait_for(pilot, lambda: "P003" in _codes(table), 5)
        assert time.monotonic() - added < 2.0
        # the overview's groups follow too
        assert app.roster.groups["novice"]["enrolled"] == 2


async def test_enrolling_past_a_target_reached_from_outside_is_asked(
    make_test_app, study_engine
) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        assert app.roster.groups["novice"] == {"target": 2, "enrolled": 1}
        pane = app.query_one("#participants-pane")
        # the command line fills the group, and ctrl+a comes before the next poll: the
        # question is decided on what the database holds at the key
        add_participant(study_engine, "novice")
        await pilot.press("ctrl+a")  # novice, the first group, is preselected
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        question = str(app.screen.query_one("#question").render())
        assert "The novice group is at 2 of 2 (full)." in question
        await pilot.press("n")
        await wait_for(pilot, lambda: pane.last_message.startswith("not enrolled"), 10)
    with Session(study_engine) as session:
        assert session.scalar(select(func.count()).select_from(Participant)) == 3


async def test_s_after_study_run_finished_the_participant_offers_no_old_trial(
    make_test_app, study_engine
) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        label = app.query_one("#next", Label)
        assert str(label.render()).startswith("next: P001 lcca/")
        # `study run` runs all of P001's trials while the app is open
        run_session(study_engine, "P001", SessionSettings("simulated", load_estimator()))
        await pilot.press("s")
        await wait_for(pilot, lambda: "trial is done" in str(label.render()), 10)
        await pilot.pause()
        assert not isinstance(app.screen, Confirm)  # no checklist asked for nothing
        assert pane.run is None
    with Session(study_engine) as session:
        assert session.scalar(select(func.count()).select_from(Trial)) == 2
