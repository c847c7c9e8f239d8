"""The NASA-TLX form by keyboard at 80 x 24: focus visible on F4, the question follows the
focus, up/down move between fields, the focused field is scrolled into view."""

from __future__ import annotations

from textual.widgets import Button, Input, Label

from study.tui.tlx_pane import TLX_SCALES, PairChoice, TlxPane
from tests.study.tui.conftest import loaded, tlx_form, wait_for


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


async def test_keys_typed_ahead_land_in_their_own_fields(make_test_app) -> None:
    # a quick operator (or a busy app) sends the whole form before the app has handled
    # its first key: every key still goes to the field the keys before it moved to
    from textual import events

    from study.protocol.tlx import pair_order

    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot)
        await wait_for(pilot, lambda: app.focused is app.query_one("#rating-mental"), 10)
        burst = ["4", "0", "down", "3", "5", "down", "1", "0", "0", "down"]
        burst += ["0", "down", "6", "5", "down", "2", "5", "down"]
        burst += ["right", "down", "left", "down", "right", "tab", "left", "shift+tab", "up"]
        for key in burst:  # posted at once: none waits for the one before to be handled
            app.post_message(events.Key(key, key if len(key) == 1 else None))
        await wait_for(pilot, lambda: app.focused is app.query_one("#pair-1"), 10)
        await pilot.pause()
        form = pane.form_state()
        assert form.ratings == ("40", "35", "100", "0", "65", "25")
        pairs = pair_order(3, "P001")  # conftest.DESIGN's seed
        # pair 1 right, 2 left, 3 right, 4 left (tab), then back up to pair 2
        assert form.choices[:5] == (pairs[0][1], pairs[1][0], pairs[2][1], pairs[3][0], None)


async def test_the_question_is_the_focused_fields_when_focus_events_come_late(
    make_test_app,
) -> None:
    # in a terminal, the form opened after a block showed no question: the participant
    # list's focus event (F4 focuses it first) arrived after the first rating's
    from textual import events

    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot)
        await wait_for(pilot, lambda: app.focused is app.query_one("#rating-mental"), 10)
        await pilot.pause()
        pane.post_message(events.DescendantFocus(app.query_one("#tlx-participant")))
        await pilot.pause()
        question = app.query_one("#question", Label)
        assert str(question.render()) == TLX_SCALES["mental"][1]


async def test_a_form_opens_with_its_block_and_question_in_view(make_test_app) -> None:
    # at 80 x 24 the form is taller than the screen: saved from its Save button, the next
    # block's form opened scrolled down, its participant, block and question hidden
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot)
        app.query_one("#save", Button).focus()
        await wait_for(pilot, lambda: pane.scroll_y > 0, 10)
        for how in ("open_block", "f4"):
            if how == "open_block":
                pane.open_block("P002", "lcca", "HV")
            else:
                app.query_one("#save", Button).focus()
                await wait_for(pilot, lambda: pane.scroll_y > 0, 10)
                await pilot.press("f2", "f4")
            await wait_for(pilot, lambda: pane.loaded_block == ("P002", "lcca", "HV"), 10)
            await wait_for(pilot, lambda: app.focused is app.query_one("#rating-mental"), 10)
            parts = ("#tlx-top", "#question", "#rating-mental")

            def in_view(parts: tuple[str, ...] = parts) -> bool:
                view = pane.scrollable_content_region
                return all(view.contains_region(app.query_one(p).region) for p in parts)

            # the scroll to the form's top lands within a few refreshes (more under load)
            await wait_for(pilot, in_view, 10)
            view = pane.scrollable_content_region
            for part in parts:
                assert view.contains_region(app.query_one(part).region), (how, part)
            assert str(app.query_one("#question", Label).render()) == TLX_SCALES["mental"][1]
