"""F2: a person types words there, so a typed word searches the list and opens no
dialog; enrolling, withdrawing and the notes are on ctrl keys."""

from __future__ import annotations

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session
from textual.widgets import DataTable, Input

from db.models.audit import AuditEntry
from db.models.study import Participant
from study.tui.confirm import Confirm, ReasonScreen
from tests.study.tui.conftest import on_screen, wait_for


def _people(engine) -> list[tuple[str, str | None, str | None]]:
    """(code, withdrawal reason, note) of everyone enrolled."""
    with Session(engine) as session:
        rows = session.scalars(select(Participant).order_by(Participant.code)).all()
        return [(p.code, p.withdrawal_reason, p.note) for p in rows]


def _audit_rows(engine) -> int:
    with Session(engine) as session:
        return len(session.scalars(select(AuditEntry)).all())


@pytest.mark.parametrize("word", ["P01", "expert", "withdrawn", "done", "a wno"])
async def test_a_word_typed_on_the_list_goes_into_find_and_opens_no_dialog(
    make_test_app, study_engine, word: str
) -> None:
    before, audited = _people(study_engine), _audit_rows(study_engine)
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        assert isinstance(app.focused, DataTable)  # F2 opens on the list
        for key in word:
            await pilot.press("space" if key == " " else key)
            assert not isinstance(app.screen, (Confirm, ReasonScreen)), key
        await pilot.pause()
        assert app.query_one("#filter", Input).value == word
        assert app.query_one("#tabs").active == "participants"
    assert _people(study_engine) == before  # nobody enrolled, withdrawn or noted
    assert _audit_rows(study_engine) == audited


@pytest.mark.parametrize("word", ["P01", "P002", "expert 2"])
async def test_a_word_typed_in_one_burst_stays_whole_in_find(make_test_app, word: str) -> None:
    """A quick typist's keys reach the app before the focus has moved to the field: the
    digits after the first letter are the word's, not the screens' 1-6."""
    from textual import events

    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        assert isinstance(app.focused, DataTable)
        for key in word:  # all sent before the app handles the first
            event = events.Key("space" if key == " " else key, key)
            event.set_sender(app)
            app._driver.send_message(event)
        await pilot.pause(0.3)
        assert app.query_one("#filter", Input).value == word
        assert app.query_one("#tabs").active == "participants"


async def test_the_find_field_narrows_the_list_to_the_typed_word(make_test_app) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        await pilot.press(*"expert")
        table = app.query_one("#people", DataTable)
        await wait_for(pilot, lambda: table.row_count == 1, 10)
        assert table.get_row_at(0)[:2] == ["P002", "expert"]


async def test_the_actions_are_on_ctrl_keys_and_still_ask(make_test_app, study_engine) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        await pilot.press("ctrl+w")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        assert "Withdraw P001?" in str(app.screen.query_one("#question").render())
        await pilot.press("escape")
        await pilot.press("ctrl+o")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        assert "P001's session" in str(app.screen.query_one("#question").render())
        await pilot.press("escape")
        await pilot.pause()
        footer = {b.binding.key for b in app.active_bindings.values() if b.binding.show}
        assert {"ctrl+a", "ctrl+w", "ctrl+n", "ctrl+o"} <= footer
        assert not {"a", "w", "n", "o"} & footer
    assert [p[1] for p in _people(study_engine)] == [None, None]
