"""The NASA-TLX form reached and kept in view at 80 x 24: from F3's notice by `t`, on F4
by default, stored ones from the palette; the block kept across participants; a docked
header; Tab cycling through the form only; a raw-only save asked once; an unchanged
save stores nothing."""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.orm import Session
from textual.widgets import Button, Input, Label, Select

from db.models.audit import AuditEntry
from db.models.tlx import TLX_SUBSCALES
from study.protocol.tlx import load_tlx, pair_order, store_tlx
from study.tui.confirm import Confirm
from study.tui.palette import study_commands
from study.tui.tlx_pane import PairChoice, TlxPane
from tests.study.tui.conftest import complete_block, loaded, run_screen, tlx_form, wait_for

RATINGS = dict(zip(TLX_SUBSCALES, (40, 35, 45, 30, 60, 25), strict=True))
SEED = 3  # the conftest design's


def _first_block(engine, code: str) -> tuple[str, str]:
    from db.models.study import Participant

    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == code)).one()
        b = min(p.blocks, key=lambda b: b.block_index)
        return b.task, b.condition


def _audit_rows(engine) -> int:
    with Session(engine) as session:
        return session.scalar(select(func.count()).select_from(AuditEntry))


async def _shown(pilot, pane: TlxPane, block: tuple[str, str, str]) -> None:
    await wait_for(pilot, lambda: pane.loaded_block == block, 10)


async def _type_ratings(pilot, values: dict[str, int]) -> None:
    for s in TLX_SUBSCALES:
        field = pilot.app.query_one(f"#rating-{s}", Input)
        field.focus()
        field.value = ""
        await pilot.press(*str(values[s]))


async def test_t_on_f3_opens_the_questionnaire_its_notice_names(
    make_test_app, study_engine
) -> None:
    task, condition = _first_block(study_engine, "P002")
    complete_block(study_engine, "P002", task, condition)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P002")
        label = app.query_one("#next", Label)
        notice = f"the NASA-TLX of {task}/{condition} is due first (t)"
        await wait_for(pilot, lambda: notice in str(label.render()), 10)
        await pilot.press("t")
        form = app.query_one(TlxPane)
        await _shown(pilot, form, ("P002", task, condition))
        assert app.query_one("#tabs").active == "tlx"
        assert app.focused is app.query_one("#rating-mental", Input)
        assert pane.run is None


async def test_f4_opens_on_the_due_questionnaire_of_the_run_screens_participant(
    make_test_app, study_engine
) -> None:
    first = ("P001", *_first_block(study_engine, "P001"))
    second = ("P002", *_first_block(study_engine, "P002"))
    for block in (first, second):
        complete_block(study_engine, *block)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")  # nobody picked on F3: the first due, in schedule order
        pane = app.query_one(TlxPane)
        await _shown(pilot, pane, first)
        assert app.query_one("#tlx-participant", Select).value == "P001"
        assert app.query_one("#tlx-block", Select).value == f"{first[1]}/{first[2]}"
        assert app.focused is app.query_one("#rating-mental", Input)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await run_screen(pilot, "P002")
        await pilot.press("f4")  # P002 picked on F3: theirs
        await _shown(pilot, app.query_one(TlxPane), second)


async def test_the_palette_finds_stored_questionnaires_too(make_test_app, study_engine) -> None:
    task, condition = _first_block(study_engine, "P001")
    complete_block(study_engine, "P001", task, condition)
    store_tlx(study_engine, "P001", task, condition, RATINGS)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        names = {name: run for name, _, run in study_commands(app)}
        stored = f"NASA-TLX of P001 {task}/{condition} (stored)"
        assert stored in names
        # nothing is due (the one finished block has its questionnaire)
        assert not [n for n in names if n.startswith("NASA-TLX of") and n != stored]
        names[stored]()
        pane = app.query_one(TlxPane)
        await _shown(pilot, pane, ("P001", task, condition))
        assert app.query_one("#rating-effort", Input).value == "60"
        assert pane.status.startswith("stored")


async def test_switching_participant_keeps_a_block_they_also_have(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot, ("P001", "lcca", "HV"))
        app.query_one("#tlx-participant", Select).value = "P002"
        await _shown(pilot, pane, ("P002", "lcca", "HV"))
        await pilot.pause(0.2)  # the block Select's own Changed message
        assert app.query_one("#tlx-block", Select).value == "lcca/HV"
        assert pane.loaded_block == ("P002", "lcca", "HV")
        assert pane.status == "new"


async def test_the_participant_and_block_stay_in_view_while_the_form_scrolls(
    make_test_app,
) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot)
        app.query_one("#pair-14", PairChoice).focus()
        await pilot.pause(0.2)
        assert pane.scroll_y > 0  # scrolled down to the last pair: the ratings out of view
        assert not pane.scrollable_content_region.overlaps(app.query_one("#rating-mental").region)
        # the first two lines of the form are still its header: whose block, the question
        for line, shown in ((0, app.query_one("#tlx-top")), (1, app.query_one("#question"))):
            widget, _ = app.screen.get_widget_at(pane.region.x + 1, pane.region.y + line)
            assert widget is shown or shown in widget.ancestors
        assert app.query_one("#tlx-participant", Select).value == "P001"
        assert app.query_one("#tlx-participant").region.y == pane.region.y
        assert "Which of the two" in str(app.query_one("#question").render())
        # the focused field is not hidden under the header
        head = app.query_one("#tlx-top").region.union(app.query_one("#question").region)
        for field in ("#pair-14", "#save", "#pair-0", "#rating-mental", "#pair-3"):
            app.query_one(field).focus()
            await pilot.pause(0.2)
            region = app.query_one(field).region
            assert pane.scrollable_content_region.contains_region(region), field
            assert not head.overlaps(region), field


async def test_tab_cycles_through_the_forms_fields_each_with_a_focus_style(
    make_test_app,
) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot)
        start = app.query_one("#rating-mental", Input)
        start.focus()
        await pilot.pause()
        # 2 lists, 6 ratings, 15 pairs, the reason, Save: 25 stops, then round again
        seen = []
        for _ in range(25):
            await pilot.press("tab")
            seen.append(app.focused)
        assert seen[-1] is start
        assert len(set(map(id, seen))) == 25
        for widget in seen:
            assert pane in widget.ancestors
            assert isinstance(widget, (Input, Select, PairChoice, Button))
            # the app's focus style: a tint over the background (a Select's on its value)
            styled = widget.children[0] if isinstance(widget, Select) else widget
            widget.focus()
            await pilot.pause()
            assert styled.styles.background_tint.a > 0, widget
        # backwards from the participant list: Save, not the tab bar
        app.query_one("#tlx-participant").focus()
        await pilot.press("shift+tab")
        assert app.focused is app.query_one("#save", Button)


async def test_ratings_without_pairwise_choices_are_stored_once_confirmed(
    make_test_app, study_engine
) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f4")
        pane = app.query_one(TlxPane)
        await _shown(pilot, pane, ("P001", "lcca", "VO"))
        await _type_ratings(pilot, RATINGS)
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        question = str(app.screen.query_one("#question").render())
        assert "no pairwise choices: store the raw score only?" in question
        await pilot.press("n")
        await pilot.pause(0.3)
        assert load_tlx(study_engine, "P001", "lcca", "VO") is None
        assert pane.status.startswith("not stored")
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: pane.status == "P001 lcca/VO: stored", 10)
        stored = load_tlx(study_engine, "P001", "lcca", "VO")
        assert stored.pairwise is None
        assert {s: getattr(stored, s) for s in TLX_SUBSCALES} == RATINGS
        # an edit of the raw-only questionnaire is not asked again
        await wait_for(pilot, lambda: pane.loaded_block == ("P001", "lcca", "VO"), 10)
        app.query_one("#rating-mental", Input).value = "45"
        app.query_one("#reason", Input).value = "misheard"
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: "updated" in pane.status, 10)
        assert not isinstance(app.screen, Confirm)
        assert load_tlx(study_engine, "P001", "lcca", "VO").mental == 45


async def test_saving_an_unchanged_stored_form_says_so_and_logs_nothing(
    make_test_app, study_engine
) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    pairs = pair_order(SEED, "P001")
    store_tlx(study_engine, "P001", "lcca", "VO", RATINGS, [a for a, _ in pairs])
    before = _audit_rows(study_engine)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await tlx_form(pilot)
        app.query_one("#rating-mental", Input).value = "040"  # the same number
        app.query_one("#reason", Input).value = "checked"
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: pane.status == "P001 lcca/VO: unchanged", 10)
        # with no reason typed too: nothing to give a reason for
        app.query_one("#reason", Input).value = ""
        pane._set_status("")
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: pane.status == "P001 lcca/VO: unchanged", 10)
        await pilot.pause(0.3)
    assert _audit_rows(study_engine) == before
