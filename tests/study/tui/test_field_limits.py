"""A refusal quotes at most 40 characters of the value it refuses (a pasted page fills one
line, not half the screen), and a free-text field shows its limit as it is typed."""

from __future__ import annotations

import re

from textual.widgets import Input, Label

from study.errors import quoted
from study.tui.char_count import CharCount
from study.tui.confirm import ReasonScreen
from tests.study.tui.conftest import loaded, tlx_form, wait_for


def test_a_quote_is_cut_to_40_characters_with_an_ellipsis() -> None:
    assert quoted("abc") == "'abc'"
    assert quoted(55) == "55"
    exactly = "x" * 40
    assert quoted(exactly) == repr(exactly)  # 40 characters: whole
    assert quoted("x" * 41) == repr("x" * 39 + "\u2026")
    long_number = int("7" * 300)
    assert quoted(long_number) == "7" * 39 + "\u2026"
    assert quoted("") == "''"


async def test_a_pasted_rating_is_refused_in_one_short_line(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot)
        app.query_one("#rating-mental", Input).value = "9" * 300
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: pane.status.startswith("refused"), 10)
        assert "mental rating " + "9" * 39 + "\u2026 is off the scale" in pane.status
        assert max(len(run) for run in re.findall("9+", pane.status)) == 39


async def test_a_note_counts_its_characters_and_a_long_one_is_refused_short(
    make_test_app,
) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        page = app.open_participant("P001")
        await pilot.pause()
        page.action_add_note()
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        await pilot.pause()
        count = app.screen.query_one(CharCount)
        assert str(count.render()) == "0/500 characters"
        await pilot.press(*"ok  then")  # runs of spaces count once, as stored
        assert str(count.render()) == "7/500 characters"
        assert not count.has_class("-over")
        app.screen.query_one("#reason-text", Input).value = "n" * 530
        await pilot.pause()
        assert str(count.render()) == "530/500 characters (too long)"
        assert count.has_class("-over")
        assert count.region.height == 1  # drawn, in the dialog
        assert count.region.width > 0
        await pilot.press("enter")
        await wait_for(pilot, lambda: "not changed" in (page.last_message or ""), 10)
        shown = page.last_message
        assert "'" + "n" * 39 + "\u2026'" in shown
        assert max(len(run) for run in re.findall("n{10,}", shown)) == 39
        assert "530 characters" in shown


async def test_a_folder_question_counts_nothing(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        app.push_screen(ReasonScreen("Export to which folder?", "folder", "exports", limit=None))
        await pilot.pause()
        assert not app.screen.query(CharCount)


async def test_the_tlx_reason_shows_its_limit(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot)
        count = pane.query_one("#reason-count", CharCount)
        assert str(count.render()) == "0/500 characters"
        pane.query_one("#reason", Input).focus()
        await pilot.press(*"misheard")
        assert str(count.render()) == "8/500 characters"
        assert isinstance(pane.query_one("#reason-count"), Label)
