"""Typing on the participants screen searches (no letter acts on a participant), and the
screens follow what another program changes in the database while the app is open."""

from __future__ import annotations

import pytest
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session
from textual.widgets import DataTable, Input, Label

from db.migrate import open_database
from db.models.audit import AuditEntry
from db.models.study import Participant
from study.protocol.roster import add_participant
from study.tui.confirm import Confirm
from tests.study.tui.conftest import complete_block, loaded, on_screen, wait_for

HINT_WORDS = ("P01", "expert", "withdrawn", "done")
"""The Find field's own hint: "code, group or state (e.g. P01, expert, withdrawn, done)"."""


@pytest.mark.parametrize("word", HINT_WORDS)
async def test_typing_a_word_on_the_list_searches_and_opens_nothing(
    make_test_app, study_engine: Engine, word: str
) -> None:
    before = _audit_rows(study_engine)
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        placeholder = app.query_one("#filter", Input).placeholder
        assert word in placeholder  # the word is one the field itself suggests
        table = app.query_one("#people", DataTable)
        assert app.focused is table  # F2 opens on the list
        for key in word:
            await pilot.press(key)
            assert app.screen is app.screen_stack[0]  # no dialog, no other screen
        await pilot.pause()
        assert app.query_one("#filter", Input).value == word
        assert app.screen is app.screen_stack[0]
        assert len(app.screen_stack) == 1
    assert _audit_rows(study_engine) == before  # and nothing was recorded
    with Session(study_engine) as session:
        assert session.scalar(select(func.count()).select_from(Participant)) == 2


def _audit_rows(engine: Engine) -> int:
    with Session(engine) as session:
        return session.scalar(select(func.count()).select_from(AuditEntry))


async def test_the_find_field_hands_back_to_the_list_and_ctrl_keys_act(
    make_test_app, study_engine: Engine
) -> None:
    from study.tui.confirm import ReasonScreen

    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        table = app.query_one("#people", DataTable)
        await pilot.press("e", "x", "p")  # P002 is the expert
        await wait_for(pilot, lambda: table.row_count == 1, 10)
        await pilot.press("enter")
        assert app.focused is table
        await pilot.press("ctrl+w")  # on the row found: asked first, naming them
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        assert "Withdraw P002?" in str(app.screen.query_one("#question").render())
        await pilot.press("enter")  # nothing typed: says what is needed, stays open
        keys = str(app.screen.query_one("#reason-keys", Label).render())
        assert keys.startswith("nothing typed: a reason is needed")
        await pilot.press("escape")


async def _rows(pilot, table: DataTable) -> list[str]:
    return [str(table.get_row_at(k)[0]) for k in range(table.row_count)]


async def test_a_participant_enrolled_from_another_connection_shows_on_f1_and_f2(
    make_test_app, study_engine: Engine
) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        table = app.query_one("#people", DataTable)
        assert await _rows(pilot, table) == ["P001", "P002"]
        other = open_database(str(study_engine.url.database))  # as `study participant add`
        try:
            add_participant(other, "novice")
            add_participant(other, "novice")
        finally:
            other.dispose()
        # the next read of the database (every POLL_S) shows them: no key pressed
        await wait_for(pilot, lambda: table.row_count == 4, 5)
        assert await _rows(pilot, table) == ["P001", "P002", "P003", "P004"]
        groups = app.query_one("#groups", DataTable)
        assert groups.get_row("novice")[1] == "3"  # F1's enrolled count too
        # the novice group (target 2) is over its target now: enrolling asks
        await pilot.press("ctrl+a")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        question = str(app.screen.query_one("#question").render())
        assert "has 3 of 2 (over target) participants" in question
        await pilot.press("n")


async def test_enrolling_asks_past_the_target_when_another_program_filled_the_group(
    make_test_app, study_engine: Engine
) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        pane = app.query_one("#participants-pane")
        pane.show = lambda roster: None  # the screen never updated: stale data
        add_participant(study_engine, "novice")  # now 2 of 2
        await pilot.press("ctrl+a")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        assert "has 2 of 2 participants" in str(app.screen.query_one("#question").render())
        await pilot.press("n")
    with Session(study_engine) as session:
        assert session.scalar(select(func.count()).select_from(Participant)) == 3


async def test_a_session_finished_elsewhere_is_not_offered_and_records_no_checklist(
    make_test_app, study_engine: Engine
) -> None:
    from study.tui.palette import study_commands
    from study.tui.run_pane import RunPane

    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f3")
        pane = app.query_one(RunPane)
        pane.select_participant("P001")
        await pilot.pause()
        assert str(app.query_one("#next", Label).render()).startswith("next: P001 ")
        # `study run` finishes P001's schedule in another process
        for block in ("lcca/VO", "lcca/HV"):
            complete_block(study_engine, "P001", *block.split("/"))
        await wait_for(
            pilot,
            lambda: "every scheduled trial is done" in str(app.query_one("#next").render()),
            5,
        )
        names = [name for name, _, _ in study_commands(app)]
        assert not any(n.startswith("Run the next trial of P001") for n in names)
        await pilot.press("s")
        await pilot.pause(0.5)
        assert not isinstance(app.screen, Confirm)  # no checklist asked
        assert pane.run is None
    with Session(study_engine) as session:
        checklists = session.scalar(
            select(func.count())
            .select_from(AuditEntry)
            .where(AuditEntry.field == "session_checklist")
        )
    assert checklists == 0


async def test_s_decides_on_fresh_data_even_before_the_screen_shows_it(
    make_test_app, study_engine: Engine, monkeypatch: pytest.MonkeyPatch
) -> None:
    from study.tui.app import StudyApp
    from study.tui.run_pane import RunPane

    monkeypatch.setattr(StudyApp, "_poll", lambda self: None)  # the screen is not told
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f3")
        pane = app.query_one(RunPane)
        pane.select_participant("P001")
        await pilot.pause()
        for block in ("lcca/VO", "lcca/HV"):
            complete_block(study_engine, "P001", *block.split("/"))
        await pilot.press("s")
        await wait_for(pilot, lambda: "every scheduled trial is done" in _next(app), 10)
        assert not isinstance(app.screen, Confirm)
    with Session(study_engine) as session:
        assert (
            session.scalar(
                select(func.count())
                .select_from(AuditEntry)
                .where(AuditEntry.field == "session_checklist")
            )
            == 0
        )


def _next(app) -> str:
    return str(app.query_one("#next", Label).render())
