"""Nothing cut at 80 x 24: the participant page's nine trial columns (a NOTES trial's
peaks and its validity), a note field that stops at its limit and shows it, and
refusals that quote at most 40 characters of what was typed."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session
from textual.widgets import DataTable, Input

from db.models.study import Participant
from db.models.trial import Trial
from study.errors import quoted
from study.protocol.free_text import MAX_TEXT_CHARS, check_free_text
from study.protocol.tlx import check_rating
from study.tui.confirm import ReasonScreen
from tests.study.tui.conftest import loaded, wait_for


def _notes_trial(engine) -> None:
    """P001: a completed, invalid NOTES trial with every peak of the task."""
    with Session(engine) as session, session.begin():
        p = session.scalars(select(Participant).where(Participant.code == "P001")).one()
        block = p.blocks[0]
        session.add(
            Trial(
                participant_id=p.id,
                block_id=block.id,
                task="notes",
                condition=block.condition,
                block_index=block.block_index,
                trial_index=0,
                status="completed",
                completion_time_s=123.45,
                success=False,
                driver="simulated",
                invalid_reason="scope slipped out of its holder",
                measure_values={
                    "peak_force_demanded_n": 12.345,
                    "peak_tip_force_n": 3.5,
                    "peak_force_rendered_n": 11.0,
                    "peak_push_n": 9.0,
                    "peak_pull_n": 4.0,
                },
            )
        )


async def test_the_trial_table_fits_80_columns(make_test_app, study_engine) -> None:
    _notes_trial(study_engine)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        page = app.open_participant("P001")
        await wait_for(pilot, lambda: page.record is not None, 10)
        await pilot.pause()
        table = page.query_one("#trials", DataTable)
        row = table.get_row_at(0)
        # the task's two headline peaks (demanded, on the fornix), then NO: invalid
        assert row[6:] == ["no", "12.35/3.50", "NO"]
        assert row[2:5] == ["trial 1", "1", "completed"]
        # every column, `valid` the last, within the table's width: no horizontal scroll
        assert table.virtual_size.width <= table.scrollable_content_region.width
        assert table.max_scroll_x == 0


async def test_the_note_field_stops_at_its_limit_and_shows_it(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        page = app.open_participant("P001")
        await wait_for(pilot, lambda: page.record is not None, 10)
        await pilot.press("a")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        field = app.screen.query_one("#reason-text", Input)
        keys = app.screen.query_one("#reason-keys")
        assert str(keys.render()).endswith(f"0/{MAX_TEXT_CHARS} characters")
        field.insert_text_at_cursor("x" * 530)  # as a paste arrives
        await pilot.pause()
        assert len(field.value) == MAX_TEXT_CHARS
        assert str(keys.render()).endswith(f"{MAX_TEXT_CHARS}/{MAX_TEXT_CHARS} characters")


def test_refusals_quote_at_most_40_characters() -> None:
    digits = "1" * 300
    assert quoted(digits) == repr("1" * 40 + "…")
    assert quoted("abc") == "'abc'"
    for check in (
        lambda: check_rating("mental", int(digits)),
        lambda: check_free_text("note", digits),
        lambda: check_free_text("note", "x" * 530),
    ):
        try:
            check()
        except ValueError as exc:
            message = str(exc)
        else:
            raise AssertionError("not refused")
        longest = max(len(word.strip("'\"…();,")) for word in message.split())
        assert longest <= 40, message
        assert len(message) < 260, message
