"""The NASA-TLX form reached and kept in view at 80 x 24: F4 opens the questionnaire the run
screen says is due, the palette finds stored ones, a new participant keeps the block,
the header stays on screen while the form scrolls, Tab goes round the form's own fields
with a visible focus, a raw-only save is asked once, an unchanged save writes nothing."""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.orm import Session
from textual.widgets import Button, Input, Label, Select

from db.models.audit import AuditEntry
from db.models.tlx import TLX_SUBSCALES, TlxResponse
from study.protocol.tlx import pair_order, store_tlx
from study.tui.confirm import Confirm
from study.tui.palette import study_commands
from study.tui.run_pane import RunPane
from study.tui.tlx_pane import TLX_SCALES, PairChoice, TlxPane
from tests.study.tui.conftest import complete_block, loaded, wait_for

RATINGS = dict(zip(TLX_SUBSCALES, (40, 35, 100, 0, 65, 25), strict=True))
SEED = 3  # conftest.DESIGN's study seed


def _audit_rows(engine) -> int:
    with Session(engine) as session:
        return session.scalar(select(func.count()).select_from(AuditEntry)) or 0


def _stored(engine) -> list[TlxResponse]:
    with Session(engine) as session:
        return list(session.scalars(select(TlxResponse)).all())


async def _form(pilot, block) -> TlxPane:
    pane = pilot.app.query_one(TlxPane)
    await wait_for(pilot, lambda: pane.loaded_block == block, 10)
    await pilot.pause()
    return pane


async def test_f4_opens_the_questionnaire_the_run_screen_says_is_due(
    make_test_app, study_engine
) -> None:
    complete_block(study_engine, "P002", "lcca", "HV")
    complete_block(study_engine, "P001", "lcca", "VO")  # P002's comes first in the due list
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f3")
        run = app.query_one(RunPane)
        run.select_participant("P001")
        await pilot.pause()
        notice = str(app.query_one("#next", Label).render())
        assert "the NASA-TLX of lcca/VO is due first (F4)" in notice
        await pilot.press("f4")
        pane = await _form(pilot, ("P001", "lcca", "VO"))
        assert app.query_one("#tlx-participant", Select).value == "P001"
        assert app.query_one("#tlx-block", Select).value == "lcca/VO"
        assert app.focused is app.query_one("#rating-mental", Input)
        # typed answers are not left behind: F4 stays on them
        await pilot.press("5", "0")
        run.select_participant("P002")
        await pilot.press("f3", "f4")
        assert pane._shown == ("P001", "lcca", "VO")
        assert pane.form_state().ratings[0] == "50"


async def test_the_palette_finds_stored_questionnaires(make_test_app, study_engine) -> None:
    complete_block(study_engine, "P002", "lcca", "HV")
    store_tlx(study_engine, "P002", "lcca", "HV", RATINGS)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        commands = {name: run for name, _, run in study_commands(app)}
        assert "NASA-TLX of P002 lcca/HV (stored)" in commands
        assert not any("P001 lcca" in name and "NASA-TLX" in name for name in commands)
        commands["NASA-TLX of P002 lcca/HV (stored)"]()
        pane = await _form(pilot, ("P002", "lcca", "HV"))
        assert pane.form_state().ratings == ("40", "35", "100", "0", "65", "25")
        assert pane.status.startswith("stored: editing it needs a reason")


async def test_another_participant_keeps_the_block(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")
        pane = app.query_one(TlxPane)
        pane.open_block("P001", "lcca", "HV")
        await _form(pilot, ("P001", "lcca", "HV"))
        app.query_one("#tlx-participant", Select).value = "P002"
        await _form(pilot, ("P002", "lcca", "HV"))
        assert app.query_one("#tlx-block", Select).value == "lcca/HV"
        # the pairs are in P002's own order
        order = pair_order(SEED, "P002")
        assert [app.query_one(f"#pair-{k}", PairChoice).pair for k in range(15)] == order


async def test_walk_of_the_form_with_its_header_in_view(make_test_app) -> None:
    # Tab from the first rating to the Save button and on round to the participant
    # list: every step has a field of the form focused (none on the tab bar or the
    # scrolling form itself), scrolled into view below the header, and the header's
    # participant, block and question on screen above it
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")
        pane = app.query_one(TlxPane)
        pane.open_block("P001", "lcca", "VO")
        await _form(pilot, ("P001", "lcca", "VO"))
        header = app.query_one("#tlx-header")
        participant, block = app.query_one("#tlx-participant"), app.query_one("#tlx-block")
        expected = [f"rating-{s}" for s in TLX_SUBSCALES[1:]]
        expected += [f"pair-{k}" for k in range(15)] + ["reason", "save"]
        expected += ["tlx-participant", "tlx-block", "rating-mental"]  # round to the top
        seen = []
        for _ in expected:
            await pilot.press("tab")
            await pilot.pause()
            focused = app.focused
            assert focused is not None, seen
            assert pane in focused.ancestors, focused
            seen.append(focused.id)
            assert header.region.y == pane.region.y  # docked at the form's top
            for widget in (participant, block):
                x, y = widget.region.x, widget.region.y
                on_top, _ = app.screen.get_widget_at(x, y)
                assert widget in (on_top, *on_top.ancestors), (focused.id, on_top)
            if header not in focused.ancestors:
                view = pane.scrollable_content_region
                assert view.contains_region(focused.region), focused.id
                assert not focused.region.overlaps(header.region), focused.id
            if focused.id == "save":
                assert pane.scroll_y > 0  # the form did scroll under the header
                assert str(app.query_one("#tlx-participant", Select).value) == "P001"
            if focused.id and focused.id.startswith("pair-"):
                assert str(app.query_one("#question", Label).render()).startswith("Which")
        assert seen == expected
        # and back: shift+tab from the participant list goes round to Save
        app.query_one("#tlx-participant").focus()
        await pilot.press("shift+tab")
        assert app.focused is app.query_one("#save", Button)
        assert str(app.query_one("#question", Label).render()) == ""
        assert TLX_SCALES  # the question labels come from the scales


async def test_the_focused_field_looks_focused(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")
        pane = app.query_one(TlxPane)
        pane.open_block("P001", "lcca", "VO")
        await _form(pilot, ("P001", "lcca", "VO"))
        for first, other in (
            ("#rating-physical", "#rating-effort"),
            ("#pair-2", "#pair-7"),
            ("#save", "#rating-mental"),
        ):
            app.query_one(other).focus()
            await pilot.pause()
            plain = app.query_one(first).rich_style.bgcolor
            app.query_one(first).focus()
            await pilot.pause()
            assert app.query_one(first).rich_style.bgcolor != plain, first


async def _type_ratings(pilot) -> None:
    app = pilot.app
    for s, value in RATINGS.items():
        field = app.query_one(f"#rating-{s}", Input)
        field.focus()
        await pilot.press("ctrl+u", *str(value))


async def test_a_raw_only_save_is_asked_once(make_test_app, study_engine) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")
        pane = await _form(pilot, ("P001", "lcca", "VO"))
        await _type_ratings(pilot)
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        question = str(app.screen.query_one("#question").render())
        assert question.startswith("no pairwise choices: store the raw score only?")
        await pilot.press("n")
        await pilot.pause()
        assert _stored(study_engine) == []
        assert pane.form_state().ratings == tuple(str(v) for v in RATINGS.values())
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: pane.status.startswith("P001 lcca/VO: stored"), 10)
        (response,) = _stored(study_engine)
        assert response.pairwise is None
        assert [getattr(response, s) for s in TLX_SUBSCALES] == list(RATINGS.values())


async def test_with_every_choice_nothing_is_asked(make_test_app, study_engine) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")
        pane = await _form(pilot, ("P001", "lcca", "VO"))
        await _type_ratings(pilot)
        for k in range(15):
            app.query_one(f"#pair-{k}", PairChoice).action_pick(k % 2)
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: pane.status.startswith("P001 lcca/VO: stored"), 10)
        assert not isinstance(app.screen, Confirm)
        (response,) = _stored(study_engine)
        order = pair_order(SEED, "P001")
        assert [c for _, _, c in response.pairwise] == [order[k][k % 2] for k in range(15)]


async def test_an_unchanged_save_says_unchanged_and_writes_nothing(
    make_test_app, study_engine
) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    store_tlx(study_engine, "P001", "lcca", "VO", RATINGS)
    before = _audit_rows(study_engine)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")
        pane = app.query_one(TlxPane)
        pane.open_block("P001", "lcca", "VO")
        await _form(pilot, ("P001", "lcca", "VO"))
        for reason in ("", "checked again"):
            app.query_one("#reason", Input).value = reason
            await pilot.press("ctrl+s")
            await pilot.pause()
            assert pane.status.startswith("P001 lcca/VO: unchanged"), pane.status
            assert _audit_rows(study_engine) == before
        # a real change is still an edit, with its row in the audit log
        field = app.query_one("#rating-mental", Input)
        field.value = "45"
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: pane.status.startswith("P001 lcca/VO: updated"), 10)
        assert _audit_rows(study_engine) > before
