"""The NASA-TLX form by keyboard at 80 x 24: focus visible on F4, the question follows the
focus, up/down move between fields, the focused field is scrolled into view."""

from __future__ import annotations

from textual.widgets import Button, Input, Label

from study.tui.tlx_pane import TLX_SCALES, PairChoice, TlxPane
from tests.study.tui.conftest import loaded, wait_for


async def test_the_form_by_keyboard(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")
        pane = app.query_one(TlxPane)
        # nothing picked yet: the participant list has the focus (Enter opens it)
        assert app.focused is app.query_one("#tlx-participant")
        pane.open_block("P001", "lcca", "VO")
        await wait_for(pilot, lambda: pane.loaded_block == ("P001", "lcca", "VO"), 10)
        await pilot.press("f2", "f4")  # back on the form: its first rating
        assert app.focused is app.query_one("#rating-mental", Input)
        question = app.query_one("#question", Label)
        assert str(question.render()) == TLX_SCALES["mental"][1]
        await pilot.press("down")
        assert app.focused is app.query_one("#rating-physical", Input)
        assert str(question.render()) == TLX_SCALES["physical"][1]
        # in the pairwise list, up/down go from pair to pair
        app.query_one("#pair-3", PairChoice).focus()
        await pilot.press("down")
        assert app.focused is app.query_one("#pair-4", PairChoice)
        await pilot.press("up", "up")
        assert app.focused is app.query_one("#pair-2", PairChoice)
        # the Save button, reached backwards from the top, is scrolled into view
        app.query_one("#rating-mental", Input).focus()
        await pilot.pause()
        save = app.query_one("#save", Button)
        while app.focused is not save:
            await pilot.press("shift+tab")
        await pilot.pause()
        assert pane.scrollable_content_region.contains_region(save.region)
