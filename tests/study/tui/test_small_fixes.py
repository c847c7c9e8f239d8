"""Small things of the terminal app's second lab day: `n` at the session checklist, the
group fill past its target, what Enter does in the export and backup dialogs, the
backup's file mode, the F3 picker's unknown code, and a refusal that names no flag."""

from __future__ import annotations

import stat
from pathlib import Path

from sqlalchemy import Engine
from textual.widgets import DataTable, Label

from study.protocol.roster import add_participant
from study.tui.confirm import Confirm, ReasonScreen
from study.tui.overview import _bar
from study.tui.picker import ParticipantPicker
from tests.study.tui.conftest import loaded, run_screen, wait_for


def _text(widget) -> str:
    return str(widget.render())


async def test_n_at_the_session_checklist_says_nothing_was_started(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        await pilot.press("s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("n")
        await pilot.pause()
        line = _text(pane.query_one("#next", Label))
        assert line == "P001: not started, the checklist is not confirmed; s asks again"
        assert pane.run is None
        # and the keys of the screen act at once
        await pilot.press("d")
        assert pane.driver_kind == "keyboard"


def test_the_fill_bar_never_draws_more_cells_than_its_width() -> None:
    assert _bar(4, 3, 16) == "█" * 16
    assert _bar(3, 3, 16) == "█" * 16
    assert _bar(1, 2, 16) == "█" * 8 + "░" * 8
    assert _bar(0, 0, 16) == "░" * 16  # no target: an empty bar, no division


async def test_a_group_over_its_target_says_so(make_test_app, study_engine: Engine) -> None:
    for _ in range(3):  # novices: 4 enrolled, the design's target is 2
        add_participant(study_engine, "novice")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        row = app.query_one("#groups", DataTable).get_row("novice")
        assert row[1:] == ["4", "2", "█" * 16 + " over target"]
        await pilot.press("f2")
        await pilot.pause()
        app.query_one("#group").value = "novice"
        await pilot.press("ctrl+a")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        question = _text(app.screen.query_one("#question"))
        assert question == (
            "The novice group is at 4 of 2 (over target). Enrol one more novice all the same?"
        )


async def test_export_and_backup_dialogs_say_what_enter_does(make_test_app, tmp_path: Path) -> None:
    app = make_test_app(backups_dir=tmp_path / "backups")
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("e")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        keys = _text(app.screen.query_one("#reason-keys"))
        assert keys == "Enter: export to this folder    Esc: cancel"
        await pilot.press("escape")
        await pilot.pause()
        await pilot.press("b")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        keys = _text(app.screen.query_one("#reason-keys"))
        assert keys == "Enter: check, then back up to this folder    Esc: cancel"
        # Enter: the copy, readable by its owner alone (as the exports are)
        await pilot.press("enter")
        pane = app.query_one("#overview-pane")
        await wait_for(pilot, lambda: "backup" in pane.last_ops_line.lower(), 30)
    copies = list((tmp_path / "backups").glob("*.db"))
    assert len(copies) == 1, pane.last_ops_line
    assert stat.S_IMODE(copies[0].stat().st_mode) == 0o600


async def test_an_unknown_code_in_the_picker_is_named(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        pane.query_one("#participant").action_show_overlay()
        await wait_for(pilot, lambda: isinstance(app.screen, ParticipantPicker), 10)
        await pilot.press(*"P099")
        await pilot.pause()
        table = app.screen.query_one("#picker-table", DataTable)
        assert [table.get_row_at(k) for k in range(table.row_count)] == [
            ["-", "", "", "no participant P099"]
        ]
        await pilot.press("enter")  # nothing to pick: the choice stays
        await pilot.pause()
        assert not isinstance(app.screen, ParticipantPicker)
        assert pane.code == "P001"


def test_a_refused_questionnaire_names_no_flag_in_the_app_and_the_flag_on_the_command_line(
    study_engine: Engine, capsys
) -> None:
    import pytest

    from db.models.tlx import TLX_SUBSCALES
    from study.cli import main
    from study.errors import ReasonNeeded
    from study.protocol.tlx import store_tlx

    with pytest.raises(ReasonNeeded) as refused:  # what the app's form shows
        store_tlx(study_engine, "P001", "lcca", "VO", dict.fromkeys(TLX_SUBSCALES, 50))
    assert str(refused.value) == (
        "P001 lcca/VO has no completed trial yet; a questionnaire for a block that has "
        "not run needs a reason, kept in the audit log"
    )
    ratings = [f"--{s}=50" for s in TLX_SUBSCALES]
    url = str(study_engine.url)
    code = main(["tlx", "enter", "--participant", "P001", "--task", "lcca", "--condition",
                 "VO", *ratings, "--db", url])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].endswith("kept in the audit log (--reason TEXT)"), err


async def test_a_note_refused_in_the_app_names_no_command_line_flag(make_test_app) -> None:
    from tests.study.tui.conftest import on_screen

    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        pane = app.query_one("#participants-pane")
        await pilot.press("ctrl+n")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        await pilot.press(*"mail a@b.org", "enter")
        await wait_for(pilot, lambda: pane.last_message.startswith("refused"), 10)
        assert pane.last_message == (
            "refused: note holds what looks like an e-mail address 'a@b.org'; expected no "
            "personal data (participants are pseudonymous codes): leave contact details out"
        )
