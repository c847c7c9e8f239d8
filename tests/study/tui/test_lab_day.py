"""A lab day's keys: digits in a form stay in the form, every shown key works
where it is shown, `?` lists the keys, and what cannot be undone is asked first."""

from __future__ import annotations

import textwrap

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session
from textual.widgets import DataTable, Input, Select, Static

from db.models.study import Participant
from study.protocol.roster import add_participant
from study.tui.confirm import Confirm, ReasonScreen
from tests.study.tui.conftest import analysed, on_screen, store_trials, wait_for


def _count(engine: Engine, group: str) -> int:
    with Session(engine) as session:
        query = select(func.count()).select_from(Participant).where(Participant.group == group)
        return session.scalar(query) or 0


def _people_at_row(app, row: int) -> DataTable:
    """The participants screen's list, focused, its cursor on `row`."""
    table = app.query_one("#people", DataTable)
    table.focus()
    table.move_cursor(row=row)
    return table


async def test_a_digit_in_a_focused_select_does_not_leave_the_form(make_test_app) -> None:
    app = make_test_app()
    async with on_screen(app, "f4") as pilot:
        pane = app.query_one("#tlx-pane")
        pane.query(Select).first().focus()
        await pilot.press("5")
        assert app.query_one("#tabs").active == "tlx"
        # away from the form's fields, the digit switches as before
        app.set_focus(None)
        await pilot.press("5")
        assert app.query_one("#tabs").active == "analysis"


async def test_ctrl_e_exports_from_inside_the_folder_field(make_test_app, tmp_path) -> None:
    app = make_test_app()
    async with on_screen(app, "f5") as pilot:
        field = app.query_one("#out-dir", Input)
        field.focus()
        field.value = str(tmp_path / "figs")
        await pilot.press("ctrl+e")
        status = app.query_one("#analysis-status", Static)
        # the export ran (this study has no trials, so it is refused with one line)
        await wait_for(
            pilot,
            lambda: "figures" in str(status.render()) or "refused" in str(status.render()),
            30,
        )
        assert str(status.render()) != "r: run the analysis; ctrl+e: export the paper's figures"
        assert field.value == str(tmp_path / "figs")


async def test_question_mark_shows_and_hides_the_keys(make_test_app) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        app.query_one("#people").focus()
        await pilot.press("question_mark")
        assert len(app.screen.query("HelpPanel")) == 1
        await pilot.press("question_mark")
        await pilot.pause()
        assert len(app.screen.query("HelpPanel")) == 0


async def test_enrolling_past_a_groups_target_is_asked_first(
    make_test_app, study_engine: Engine
) -> None:
    add_participant(study_engine, "novice")  # DESIGN's novice target is 2: now full
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        pane = app.query_one("#participants-pane")
        await pilot.press("ctrl+a")  # novice, the first group, is preselected
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        assert "is at 2 of 2 (full)" in str(app.screen.query_one("#question").render())
        await pilot.press("n")
        await wait_for(pilot, lambda: pane.last_message.startswith("not enrolled"), 10)
        assert pane.last_message == "not enrolled: the novice group is full"
        assert _count(study_engine, "novice") == 2
        await pilot.press("ctrl+a")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: pane.last_message.startswith("enrolled"), 30)
    assert _count(study_engine, "novice") == 3


async def test_analysis_prints_p_as_apa_labels_effects_and_shows_notes_and_anova(
    make_test_app, study_engine: Engine
) -> None:
    import re

    from textual.widgets import DataTable

    store_trials(study_engine)  # 3 novices, 3 experts, one trial per condition each
    app = make_test_app()
    async with app.run_test(size=(100, 30)) as pilot:
        await analysed(pilot)
        table = app.query_one("#comparisons", DataTable)
        rows = [table.get_row_at(k) for k in range(table.row_count)]
        for row in rows:
            assert re.fullmatch(r"< \.001|\.\d{3}|n/a", row[7]), row[7]  # APA: no "0.000"
            assert re.fullmatch(r"(g_av|r_rb)\n[+-]\d\.\d\d|n/a", row[8]), row[8]
            assert row[8].startswith("g_av") == (row[6] == "t") or row[8] == "n/a"
        await pilot.press("n")
        await wait_for(pilot, lambda: len(app.screen.query("#text")) == 1, 10)
        text = str(app.screen.query_one("#text", Static).render())
        assert "Exclusions:" in text
        assert "Notes:" in text
        # 6 participants in 2 groups: the condition effect has df (1, 6 - 2)
        assert re.search(r"lcca/peak_proximal_force_n condition: F\(1, 4\) = \d", text)
        await pilot.press("escape")
        await wait_for(pilot, lambda: len(app.screen.query("#text")) == 0, 10)


async def test_typed_answers_survive_switching_blocks_and_quitting_asks(make_test_app) -> None:
    from study.tui.tlx_pane import PairChoice
    from tests.study.tui.test_screens import _open_form

    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _open_form(pilot, "P001", "lcca/VO")
        app.query_one("#rating-mental", Input).focus()
        await pilot.press("7", "0")
        app.query_one("#rating-physical", Input).value = "70"
        app.query_one("#pair-0", PairChoice).action_pick(1)
        picked = app.query_one("#pair-0", PairChoice).choice
        # to the HV block: its own (empty) form
        app.query_one("#tlx-block", Select).value = "lcca/HV"
        await wait_for(pilot, lambda: pane.status == "new" and pane._shown[2] == "HV", 10)
        assert app.query_one("#rating-mental", Input).value == ""
        # and back: what was typed is there, said to be a draft
        app.query_one("#tlx-block", Select).value = "lcca/VO"
        await wait_for(pilot, lambda: pane.status.startswith("draft restored"), 10)
        assert app.query_one("#rating-mental", Input).value == "70"
        assert app.query_one("#rating-physical", Input).value == "70"
        assert app.query_one("#pair-0", PairChoice).choice == picked
        # quitting with it unsaved asks; "n" stays
        await pilot.press("ctrl+q")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        assert "P001 lcca/VO" in str(app.screen.query_one("#question").render())
        await pilot.press("n")
        await pilot.pause()
        assert app.is_running


async def test_withdrawing_from_the_list_asks_why_and_marks_the_row(
    make_test_app, study_engine: Engine
) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        table = _people_at_row(app, 1)  # P002
        await pilot.press("ctrl+w")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        await pilot.press("escape")  # cancelled: nothing recorded
        await pilot.pause()
        await pilot.press("ctrl+w")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        await pilot.press(*"ended early", "enter")
        await wait_for(pilot, lambda: table.get_row("P002")[4] == "withdrawn: ended early", 30)
        # the run screen says so instead of offering the next trial
        await pilot.press("f3")
        app.query_one("#run-pane").select_participant("P002")
        await pilot.pause()
        assert "P002 withdrew (ended early): no more sessions" in str(
            app.query_one("#next").render()
        )
    with Session(study_engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == "P002")).one()
        p1 = session.scalars(select(Participant).where(Participant.code == "P001")).one()
    assert p.withdrawal_reason == "ended early"
    assert p1.withdrawn_at is None


async def test_the_chart_follows_a_resize_and_the_form_opens_on_its_first_rating(
    make_test_app, study_engine: Engine
) -> None:
    store_trials(study_engine)
    app = make_test_app()
    async with app.run_test(size=(120, 30)) as pilot:
        pane = await analysed(pilot)
        chart = app.query_one("#chart", Static)
        await wait_for(pilot, lambda: "novice" in str(chart.render()), 10)

        def longest() -> int:
            return max(line.count("█") for line in str(chart.render()).splitlines())

        wide = longest()
        await pilot.resize_terminal(80, 24)
        await wait_for(pilot, lambda: longest() < wide, 10)
        # the longest bar fills the new width (content width - 24 columns of labels)
        assert longest() == max(pane.content_size.width - 24, 10)
        # a block's questionnaire opens with the first rating focused
        app.query_one("#tlx-pane").open_block("P001", "lcca", "VO")
        await pilot.pause()
        assert app.focused is app.query_one("#rating-mental", Input)


async def test_a_finished_participant_leads_to_the_next_one(
    make_test_app, study_engine: Engine
) -> None:
    from tests.study.tui.conftest import complete_block

    for condition in ("VO", "HV"):  # P001's whole schedule: one trial per block
        complete_block(study_engine, "P001", "lcca", condition)
    app = make_test_app()
    async with on_screen(app, "f3") as pilot:
        pane = app.query_one("#run-pane")
        pane.select_participant("P001")
        await pilot.pause()
        label = app.query_one("#next")
        # its questionnaires not entered yet: the first is named, and `t` opens it
        assert str(label.render()) == (
            "P001: every trial is done; the NASA-TLX of lcca/VO is due (t); n: on to P002"
        )
        pane.focus()
        await pilot.press("n")
        await pilot.pause()
        assert pane.code == "P002"
        assert str(label.render()).startswith("next: P002 lcca/")


async def test_the_participant_list_can_be_searched(make_test_app, study_engine: Engine) -> None:
    from textual.widgets import DataTable

    add_participant(study_engine, "novice")
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        table = app.query_one("#people", DataTable)
        await wait_for(pilot, lambda: table.row_count == 3)
        app.query_one("#filter", Input).focus()
        await pilot.press(*"EXPERT")  # any case, any column
        await wait_for(pilot, lambda: table.row_count == 1)
        assert table.get_row_at(0)[1] == "expert"
        await pilot.press(*["backspace"] * 6, *"p003")
        await wait_for(pilot, lambda: table.row_count == 1)
        assert table.get_row_at(0)[0] == "P003"
        await pilot.press(*["backspace"] * 4)
        await wait_for(pilot, lambda: table.row_count == 3)


async def test_tab_into_the_folder_field_and_a_key_does_not_replace_the_path(
    make_test_app, tmp_path
) -> None:
    app = make_test_app(figures_dir=tmp_path / "figs")
    async with on_screen(app, "f5") as pilot:
        field = app.query_one("#out-dir", Input)
        while app.focused is not field:
            await pilot.press("tab")
        await pilot.press("r")
        assert field.value in (str(tmp_path / "figs"), str(tmp_path / "figs") + "r")
        assert field.value != "r"


async def test_notes_on_a_participant_and_on_their_session_from_the_list(
    make_test_app, study_engine: Engine
) -> None:
    from db.models.audit import AuditEntry

    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        _people_at_row(app, 1)  # P002
        notes = (
            ("ctrl+n", "left-handed grip"),
            ("ctrl+o", "dial recalibrated"),
            ("ctrl+o", "fire alarm, 5 min pause"),
            ("ctrl+n", "; prefers the left hand"),  # added to the note, shown as it stands
        )
        for key, text in notes:
            await pilot.press(key)
            await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
            assert "no names or contact details" in str(app.screen.query_one("#question").render())
            if text.startswith(";"):
                field = app.screen.query_one("#reason-text", Input)
                assert field.value == "left-handed grip"
                await wait_for(
                    pilot,
                    lambda: "note: left-handed grip" in str(app.query_one("#detail").render()),
                    10,
                )
            await pilot.press(*text, "enter")
            kind = "session note" if key == "ctrl+o" else "note"
            await wait_for(
                pilot,
                lambda kind=kind: any(
                    f"P002: {kind} kept" in str(w.render()) for w in app.query("#add-status")
                ),
                30,
            )
    with Session(study_engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == "P002")).one()
        sessions = session.scalars(
            select(AuditEntry.new_value)
            .where(AuditEntry.field == "session_note")
            .order_by(AuditEntry.id)
        ).all()
    # the participant's note is replaced; the session notes are kept, each its own row
    assert p.note == "left-handed grip; prefers the left hand"
    assert sessions == ["dial recalibrated", "fire alarm, 5 min pause"]


async def test_a_long_question_wraps_inside_its_box(make_test_app) -> None:
    # the session checklist is longer than the 60-column box: it wraps, nothing is cut
    question = (
        "Session checklist for P001: consent confirmed and the device checked? "
        "(recorded with the session)"
    )
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        app.push_screen(Confirm(question))
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.pause()
        label = app.screen.query_one("#question")
        box = app.screen.query_one("#confirm")
        assert label.region.right <= box.region.right
        # as many rows as the question takes, wrapped at words to the label's width
        assert label.size.height == len(textwrap.wrap(question, label.size.width)) >= 2
