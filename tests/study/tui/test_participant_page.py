"""The participant page, the F3 picker and the command palette, under Textual's pilot.

The page shows what is stored about one participant (trials with attempts and
interrupted ones, notes, TLX per block, probes, the schedule in its order) and makes the
audited corrections by key; the picker shows group, progress and next trial and searches
by code; ctrl+p offers the app's own commands."""

from __future__ import annotations

from sqlalchemy import Engine, select
from sqlalchemy.orm import Session
from textual.widgets import DataTable, Select

from db.models.audit import AuditEntry
from db.models.probe import ProbeTrial
from db.models.study import Participant
from db.models.tlx import TLX_SUBSCALES
from db.models.trial import Trial
from study.protocol.roster import add_participant
from study.protocol.session import recover_interrupted
from study.protocol.tlx import store_tlx
from study.protocol.withdrawal import add_session_note, set_note, withdraw
from study.tui.confirm import ReasonScreen
from study.tui.participant_page import GroupScreen, ParticipantPage
from study.tui.picker import ParticipantPicker
from study.tui.run_pane import RunPane
from tests.study.tui.conftest import loaded, wait_for


def _text(app, selector: str) -> str:
    return str(app.screen.query_one(selector).render())


def _first_block_done(engine: Engine) -> tuple[list[str], int, int]:
    """P001 (novice): an interrupted attempt, then the completed trial of their first
    block (peaks 1.25 and 0.5 N, 31.5 s, success), its NASA-TLX, 3 probe trials, a note
    and a session note. Returns their condition order, the interrupted and the completed
    trial's ids."""
    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == "P001")).one()
        order, first = list(p.condition_order), p.blocks[0]
        common = {
            "participant_id": p.id,
            "block_id": first.id,
            "task": "lcca",
            "condition": first.condition,
            "block_index": 0,
            "trial_index": 0,
            "driver": "simulated",
        }
        stopped = Trial(**common, attempt=1, status="running")
        session.add(stopped)
        session.commit()
        pid, stopped_id = p.id, stopped.id
    recover_interrupted(engine, pid, "stopped: fire alarm")
    with Session(engine) as session:
        done = Trial(
            **common,
            attempt=2,
            status="completed",
            completion_time_s=31.5,
            success=True,
            measure_values={"peak_proximal_force_n": 1.25, "peak_distal_force_n": 0.5},
        )
        session.add(done)
        for k in range(3):
            session.add(
                ProbeTrial(
                    participant_id=pid,
                    probe="reaction_time",
                    trial_index=k,
                    stimulus=1.0,
                    response=0.3,
                    correct=None,
                    context={},
                    driver="simulated",
                )
            )
        session.commit()
        done_id = done.id
    store_tlx(engine, "P001", "lcca", order[0], dict.fromkeys(TLX_SUBSCALES, 50))
    set_note(engine, "P001", "wears glasses", "EXP01")
    add_session_note(engine, "P001", "dial recalibrated", "EXP02")
    return order, stopped_id, done_id


async def test_the_page_shows_what_is_stored_and_makes_audited_corrections(
    make_test_app, study_engine: Engine
) -> None:
    order, stopped_id, done_id = _first_block_done(study_engine)
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f2")  # the list has the focus, P001 under the cursor
        await pilot.press("enter")
        await wait_for(pilot, lambda: isinstance(app.screen, ParticipantPage), 10)
        page = app.screen
        await wait_for(pilot, lambda: page.record is not None, 10)
        a, b = order
        assert _text(app, "#who") == f"P001 (novice): conditions {a} -> {b}; in the study"
        assert _text(app, "#schedule") == (
            f"schedule: 1 lcca/{a} 1/1 TLX stored, next 2 lcca/{b} 0/1"
        )
        assert _text(app, "#probes") == "probes: reaction_time 3 trials"
        table = page.query_one("#trials", DataTable)
        rows = [table.get_row_at(k) for k in range(table.row_count)]
        assert rows == [
            [str(stopped_id), f"1 lcca/{a}", "1", "1", "interrupted", "-", "-", "-", "-"],
            [str(done_id), f"1 lcca/{a}", "1", "2", "completed", "31.5", "yes", "1.25/0.50", "yes"],
        ]
        # the highlighted row in full: why it was interrupted
        assert _text(app, "#trial-detail") == (
            f"trial {stopped_id}, lcca/{a} trial 1, attempt 1: interrupted (stopped: fire alarm)"
        )
        notes = _text(app, "#notes").splitlines()
        assert notes[0] == "note: wears glasses"
        assert notes[1].endswith("EXP01 note set: wears glasses")
        assert notes[2].endswith("EXP02 added: dial recalibrated")
        # not withdrawn: no undo offered
        await pilot.pause(0.2)
        keys = {k.key for k in app.screen.query("FooterKey")}
        assert {"i", "a", "e", "g", "escape"} <= keys
        assert "u" not in keys
        # i on the interrupted row: refused in one line, nothing asked
        await pilot.press("i")
        await pilot.pause()
        assert page.last_message == (
            f"trial {stopped_id} is interrupted; only a completed measured trial is marked"
        )
        # i on the completed trial: asked why, marked invalid, audited, shown
        await pilot.press("down", "i")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        await pilot.press(*"sensor cable loose", "enter")
        await wait_for(pilot, lambda: "marked invalid" in page.last_message, 10)
        await wait_for(pilot, lambda: table.get_row_at(1)[8] == "NO")
        assert _text(app, "#trial-detail") == (
            f"trial {done_id}, lcca/{a} trial 1, attempt 2: completed in 31.50 s, success; "
            "INVALID: sensor cable loose\npeak proximal force 1.25 N, peak distal force 0.5 N"
        )
        # i again: valid again
        await pilot.press("i")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        assert "again in the analysis" in str(app.screen.query_one("#question").render())
        await pilot.press(*"cable was fine", "enter")
        await wait_for(pilot, lambda: "valid again" in page.last_message, 10)
        # a: a note added to the history; e: the standing note, opened as it stands
        await pilot.press("a")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        assert app.screen.query_one("#reason-text").value == ""
        await pilot.press(*"tired after block 1", "enter")
        await wait_for(pilot, lambda: "added: tired after block 1" in _text(app, "#notes"), 10)
        await pilot.press("e")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        assert app.screen.query_one("#reason-text").value == "wears glasses"
        await pilot.press(*", left-handed", "enter")
        await wait_for(
            pilot, lambda: _text(app, "#notes").startswith("note: wears glasses, left-handed")
        )
        # withdrawn elsewhere: u undoes it, with a reason
        withdraw(study_engine, "P001", "felt unwell")
        page.reload()
        await wait_for(pilot, lambda: "withdrawn: felt unwell" in _text(app, "#who"), 10)
        # the longest footer (u offered too): every key whole within 80 columns
        await pilot.pause(0.2)
        footer = list(app.screen.query("FooterKey"))
        assert {k.key for k in footer} >= {"escape", "i", "a", "e", "u", "g", "question_mark"}
        assert all(0 < k.region.width and k.region.right <= 80 for k in footer)
        regions = [k.region for k in footer]  # none drawn over another (a docked hint)
        assert not any(r.overlaps(q) for n, r in enumerate(regions) for q in regions[n + 1 :])
        await pilot.press("u")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        await pilot.press(*"better after a rest", "enter")
        await wait_for(pilot, lambda: _text(app, "#who").endswith("in the study"), 10)
        await pilot.press("g")
        await pilot.pause()
        assert page.last_message == (
            "P001 has trials stored: the group can be corrected only before the first trial"
        )
        await pilot.press("escape")
        await wait_for(pilot, lambda: not isinstance(app.screen, ParticipantPage), 10)
    with Session(study_engine) as session:
        trial = session.get_one(Trial, done_id)
        assert trial.invalid_reason is None
        audit = session.scalars(select(AuditEntry).order_by(AuditEntry.id)).all()
        p = session.scalars(select(Participant).where(Participant.code == "P001")).one()
    changes = [(e.field, e.old_value, e.new_value, e.reason) for e in audit]
    assert ("validity", "valid", "invalid", "sensor cable loose") in changes
    assert ("validity", "invalid", "valid", "cable was fine") in changes
    assert ("status", "withdrawn", "enrolled", "better after a rest") in changes
    assert ("note", "wears glasses", "wears glasses, left-handed", "note edited") in changes
    assert [e.new_value for e in audit if e.field == "session_note"] == [
        "dial recalibrated",
        "tired after block 1",
    ]
    assert (p.note, p.withdrawn_at) == ("wears glasses, left-handed", None)


async def test_the_group_is_corrected_from_the_page_before_the_first_trial(
    make_test_app, study_engine: Engine
) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        page = app.open_participant("P001")
        await wait_for(pilot, lambda: page.record is not None, 10)
        await pilot.pause(0.2)
        assert "g" in {k.key for k in app.screen.query("FooterKey")}
        await pilot.press("g")
        await wait_for(pilot, lambda: isinstance(app.screen, GroupScreen), 10)
        app.screen.query_one("#new-group", Select).value = "expert"
        app.screen.query_one("#group-reason").focus()
        await pilot.press(*"ticked the wrong box", "enter")
        await wait_for(pilot, lambda: _text(app, "#who").startswith("P001 (expert)"), 10)
        assert "P001 moved to expert" in page.last_message
    with Session(study_engine) as session:
        entry = session.scalars(select(AuditEntry).where(AuditEntry.field == "group")).one()
        assert entry.reason == "ticked the wrong box"
        p = session.scalars(select(Participant).where(Participant.code == "P001")).one()
        assert p.group == "expert"


async def test_the_f3_picker_shows_group_and_next_trial_and_searches_by_code(
    make_test_app, study_engine: Engine
) -> None:
    add_participant(study_engine, "novice")  # P003
    with Session(study_engine) as session:
        orders = {
            p.code: list(p.condition_order) for p in session.scalars(select(Participant)).all()
        }
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f3", "enter")
        await wait_for(pilot, lambda: isinstance(app.screen, ParticipantPicker), 10)
        table = app.screen.query_one("#picker-table", DataTable)
        rows = [table.get_row_at(k) for k in range(table.row_count)]
        assert rows == [
            ["-", "", "", "(no change)"],
            ["P001", "novice", "0/2", f"lcca/{orders['P001'][0]} trial 1, block 1"],
            ["P002", "expert", "0/2", f"lcca/{orders['P002'][0]} trial 1, block 1"],
            ["P003", "novice", "0/2", f"lcca/{orders['P003'][0]} trial 1, block 1"],
        ]
        await pilot.press(*"03")
        await pilot.pause()
        assert [table.get_row_at(k)[0] for k in range(table.row_count)] == ["P003"]
        await pilot.press("backspace", "backspace", *"expert")
        await pilot.pause()
        assert [table.get_row_at(k)[0] for k in range(table.row_count)] == ["P002"]
        await pilot.press("enter")
        await wait_for(pilot, lambda: app.query_one(RunPane).code == "P002", 10)
        # Esc leaves the choice as it was
        await pilot.press("enter")
        await wait_for(pilot, lambda: isinstance(app.screen, ParticipantPicker), 10)
        await pilot.press(*"P001", "escape")
        await pilot.pause()
        assert app.query_one(RunPane).code == "P002"
        # v: the picked participant's page
        await pilot.press("v")
        await wait_for(pilot, lambda: isinstance(app.screen, ParticipantPage), 10)
        assert app.screen.code == "P002"


async def test_the_palette_offers_the_apps_own_commands(
    make_test_app, study_engine: Engine
) -> None:
    from study.tui.palette import study_commands

    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        names = [name for name, _, _ in study_commands(app)]
        for expected in (
            "Enrol a participant in novice",
            "Participant page: P002 (expert)",
            "Add a note to P001",
            "Withdraw P002",
            "Analysis: Analyse",
            "Analysis: Export figures",
        ):
            assert expected in names
        assert any(n.startswith("Run the next trial of P001: lcca/") for n in names)
        # through the palette by keys: the page of P002
        await pilot.press("ctrl+p")
        await pilot.pause(0.3)
        await pilot.press(*"Participant page: P002")
        await pilot.pause(0.5)
        await pilot.press("enter")
        await wait_for(pilot, lambda: isinstance(app.screen, ParticipantPage), 10)
        assert app.screen.code == "P002"
        await pilot.press("escape")
        await pilot.pause()
        # enrolling from the palette: one more novice
        await pilot.press("ctrl+p")
        await pilot.pause(0.3)
        await pilot.press(*"Enrol a participant in novice")
        await pilot.pause(0.5)
        await pilot.press("enter")
        await wait_for(pilot, lambda: len(app.roster.participants) == 3, 10)
    with Session(study_engine) as session:
        groups = session.scalars(select(Participant.group).order_by(Participant.id)).all()
    assert groups == ["novice", "expert", "novice"]


async def test_f5_leaves_an_invalid_trial_out_and_lists_it_with_its_reason(
    make_test_app, study_engine: Engine
) -> None:
    from study.protocol.corrections import mark_trial
    from study.tui.confirm import TextScreen
    from tests.study.tui.conftest import analysed, store_trials

    store_trials(study_engine)
    with Session(study_engine) as session:
        trial_id, code = session.execute(
            select(Trial.id, Participant.code)
            .join(Participant)
            .where(Participant.group == "expert", Trial.condition == "HV")
            .order_by(Participant.code)
        ).first()
    mark_trial(study_engine, trial_id, False, "alarm went off", "EXP01")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await analysed(pilot)
        line = f"lcca/all measures: excluded {code} HV trial 1 (marked invalid: alarm went off)"
        assert line in pane.result.exclusions
        [row] = [
            d
            for d in pane.result.descriptives.to_dict("records")
            if d["measure"] == "peak_proximal_force_n"
            and d["group"] == "expert"
            and d["condition"] == "HV"
        ]
        # the other two experts' HV peaks (PEAKS, by hand): (0.5 + 0.9) / 2
        assert row["n"] == 2
        assert abs(row["mean"] - 0.7) < 1e-12
        await pilot.press("n")
        await wait_for(pilot, lambda: isinstance(app.screen, TextScreen), 10)
        assert line in app.screen.text


NOTES_DESIGN = """\
name = "notes page"
seed = 3
tasks = ["notes"]
trials_per_condition = 2
practice_trials = 0
[groups]
novice = 2
"""
NOTES_PEAKS = {  # a NOTES trial's stored measures, distinct values, in the task's order
    "peak_force_demanded_n": 10.11,
    "peak_tip_force_n": 6.94,
    "peak_force_rendered_n": 5.98,
    "peak_torque_demanded_n_m": 0.0698,
    "peak_torque_rendered_n_m": 0.0704,
    "peak_push_n": 10.11,
    "peak_pull_n": 4.95,
    "peak_torque_cw_n_m": 0.0634,
    "peak_torque_ccw_n_m": 0.0671,
    "push_over_capacity_fraction": 0.199,
}
NOTES_SHOWN = (  # the detail line of such a trial, three significant figures, by hand
    "peak demanded force 10.1 N, peak tip force 6.94 N, peak rendered force 5.98 N, "
    "peak demanded torque 0.0698 N m, peak rendered torque 0.0704 N m, peak push 10.1 N, "
    "peak pull 4.95 N, peak CW torque 0.0634 N m, peak CCW torque 0.0671 N m, "
    "push over capacity 0.199"
)


async def test_a_notes_trial_is_shown_whole_at_80_columns(tmp_path) -> None:
    from db.migrate import open_database
    from study.protocol.design import parse_design
    from study.protocol.roster import create_study
    from study.tui import StudyServices, TuiSettings, make_app
    from tests.study.tui.conftest import screen_text

    engine = open_database(str(tmp_path / "notes.db"), create=True)
    create_study(engine, parse_design(NOTES_DESIGN), NOTES_DESIGN)
    add_participant(engine, "novice")
    with Session(engine) as session, session.begin():
        p = session.scalars(select(Participant)).one()
        first = p.blocks[0]
        cond = first.condition
        for k in range(2):
            session.add(
                Trial(
                    participant_id=p.id,
                    block_id=first.id,
                    task="notes",
                    condition=first.condition,
                    block_index=0,
                    trial_index=k,
                    status="completed",
                    completion_time_s=40.36,
                    success=True,
                    driver="simulated",
                    measure_values=NOTES_PEAKS,
                )
            )
    reason = (
        "the phantom slipped on the table, the fornix insert moved by two centimetres "
        "and was put back"
    )
    app = make_app(StudyServices(engine, None), TuiSettings(prepare_simulation=False))
    try:
        async with app.run_test(size=(80, 24)) as pilot:
            await loaded(pilot)
            await pilot.press("f2", "enter")
            await wait_for(pilot, lambda: isinstance(app.screen, ParticipantPage), 10)
            page = app.screen
            await wait_for(pilot, lambda: page.record is not None, 10)
            await pilot.press("down", "i")
            await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
            await pilot.press(*reason, "enter")
            await wait_for(pilot, lambda: "marked invalid" in page.last_message, 10)
            table = page.query_one("#trials", DataTable)
            await wait_for(pilot, lambda: table.get_row_at(1)[8] == "NO", 10)
            await pilot.pause(0.2)
            rows = screen_text(app).splitlines()
    finally:
        engine.dispose()
    # every column in view, the validity last, the analysed peaks whole
    header = next(r for r in rows if r.lstrip().startswith("id "))
    assert header.split() == [
        "id",
        "block",
        "trial",
        "att",
        "status",
        "time",
        "s",
        "ok",
        "peaks",
        "N",
        "valid",
    ]
    trial_rows = [
        r.split()
        for r in rows
        if r.split()[1:3] + r.split()[5:6] == ["1", f"notes/{cond}", "completed"]
    ]
    assert [r[-3:] for r in trial_rows] == [
        ["yes", "10.11/6.94", "yes"],
        ["yes", "10.11/6.94", "NO"],
    ]
    # the highlighted trial's every measure and its reason, and the confirmation, uncut
    text = " ".join(r.strip() for r in rows)
    assert f"INVALID: {reason} {NOTES_SHOWN}" in text
    ids = [r[0] for r in trial_rows]
    assert (
        f"trial {ids[1]} (P001 notes/{cond} trial 2 (attempt 1)) marked invalid ({reason})" in text
    )
    assert "(P001 notes" not in rows[-1]  # the key line stays the last row
