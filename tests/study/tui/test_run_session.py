"""The run-session screen: a simulated trial to its end, quitting in the middle of one, and
NOTES trials (their own live view; the keyboard drives them too)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session
from textual.widgets import Label

from db.migrate import open_database
from db.models.audit import AuditEntry
from db.models.study import ScheduleBlock
from db.models.tlx import TLX_SUBSCALES
from db.models.trial import SampleChunk, Trial
from study.protocol.default_estimator import load_estimator
from study.protocol.design import parse_design
from study.protocol.roster import add_participant, create_study
from study.protocol.tasks import get_task
from study.protocol.tlx import store_tlx
from study.tui import StudyServices, TuiSettings, make_app
from study.tui.confirm import Confirm
from study.tui.run_pane import RunPane
from study.tui.scene_lcca import PhantomView
from study.tui.scene_notes import NotesView
from study.tui.stop_dialog import StopScreen
from study.tui.tlx_pane import TlxPane
from study.tui.trial_runner import STOPPED_REASON
from tests.study.conftest import stored_samples
from tests.study.tui.conftest import run_screen, screen_text, wait_for


def _trials(engine) -> list[tuple[str, str, int]]:
    """(status, driver, samples) of every trial."""
    with Session(engine) as session:
        rows = session.execute(select(Trial.id, Trial.status, Trial.driver)).all()
        return [
            (status, driver, session.scalar(stored_samples(tid))) for tid, status, driver in rows
        ]


async def _start(pilot, code: str, *keys: str) -> RunPane:
    """On the run screen, pick `code`, press `keys` (driver, pace), start the trial."""
    pane = await run_screen(pilot, code)
    await pilot.press(*keys, "s")
    # the session checklist, asked before a participant's first trial in the app
    await wait_for(pilot, lambda: isinstance(pilot.app.screen, Confirm), 10)
    assert "consent confirmed" in str(pilot.app.screen.query_one("#question").render())
    await pilot.press("y")
    return pane


async def test_a_simulated_trial_runs_to_its_end_and_opens_the_questionnaire(
    make_test_app,
    study_engine,
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=None)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _start(pilot, "P001")
        await wait_for(pilot, lambda: pane.status == "completed", 120)
        # the stored trial's figures, then (one trial per block) the block's
        shown = pane.last_outcome.split("\n")
        assert shown[0] == "P001: lcca/VO trial 1 stored"
        assert "block lcca/VO done:" in shown
        assert "  1 measured trial, mean ± SD" in shown
        # the live view was fed while the trial ran
        assert app.query_one(PhantomView)._frame is not None
        # one trial per block in DESIGN: the block is done, the form opens for it
        await wait_for(pilot, lambda: app.query_one("#tabs").active == "tlx")
        await wait_for(pilot, lambda: app.query_one(TlxPane).status == "new")
        # the session flow: the next block waits for this block's questionnaire ...
        await pilot.press("f3")
        await pilot.press("s")
        label = app.query_one("#next", Label)
        await wait_for(pilot, lambda: "the NASA-TLX of lcca/VO is due first" in str(label.render()))
        assert pane.run is None
        store_tlx(study_engine, "P001", "lcca", "VO", dict.fromkeys(TLX_SUBSCALES, 50))
        app.reload()
        await wait_for(pilot, lambda: not app.query_one(RunPane).roster.tlx_due(), 30)
        # ... and the design's break is counted down; starting early is asked first
        await wait_for(pilot, lambda: str(label.render()).startswith("break: 1:"), 10)
        await pilot.press("s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        assert "break after the last block has" in str(app.screen.query_one("#question").render())
        await pilot.press("n")
        await pilot.pause()
        assert pane.run is None
    with Session(study_engine) as session:
        trial = session.scalars(select(Trial)).one()
        n = session.scalar(select(func.coalesce(func.sum(SampleChunk.n_samples), 0)))
    assert (trial.status, trial.driver, trial.condition) == ("completed", "simulated", "VO")
    success = "yes" if trial.success else "no"
    assert shown[1:3] == [
        f"  success {success}",
        f"  completion time {trial.completion_time_s:.1f} s",
    ]
    peak = trial.measure_values["peak_proximal_force_n"]
    assert f"  peak proximal force {peak:.2f} N" in shown  # the stored peak
    with Session(study_engine) as session:
        checklist = session.scalars(
            select(AuditEntry).where(AuditEntry.field == "session_checklist")
        ).one()
    assert checklist.new_value == "consent confirmed; device checked"
    # one 100 Hz sample per 10 ms of the trial, as `study run` stores them
    assert n == round(trial.completion_time_s * 100) == trial.summary["samples"]


async def test_quitting_mid_trial_marks_it_interrupted_and_keeps_its_samples(
    make_test_app,
    study_engine,
) -> None:
    app = make_test_app(load_estimator=load_estimator, simulated_pace=1.0)
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _start(pilot, "P002", "d")  # d: the keyboard drives
        await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 20, 120)
        await pilot.press("up", "up", "up")
        shown = pane.run.live.frame().t_s
        await pilot.press("ctrl+q")
        # a trial is running: asked first, and "n" keeps it running
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("n")
        assert app.is_running
        assert pane.run is not None
        await pilot.press("ctrl+q")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: not app.is_running, 30)
    [(status, driver, samples)] = _trials(study_engine)
    assert (status, driver) == ("interrupted", "keyboard")
    # everything up to the last batch the view showed is stored (at 100 Hz)
    assert samples >= round(shown * 100)
    with Session(study_engine) as session:
        entry = session.scalars(select(AuditEntry).where(AuditEntry.field == "status")).one()
    assert (entry.old_value, entry.new_value, entry.reason) == (
        "running",
        "interrupted",
        STOPPED_REASON,
    )


NOTES_DESIGN = """\
name = "tui notes"
seed = 4
tasks = ["notes"]
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 1
"""


def trial_condition(engine: Engine) -> str:
    """The condition of the one participant's first block."""
    with Session(engine) as session:
        return session.scalars(
            select(ScheduleBlock.condition).order_by(ScheduleBlock.block_index)
        ).first()


@pytest.fixture
def notes_engine(tmp_path: Path) -> Iterator[Engine]:
    """A NOTES-only study with P001 (novice) enrolled."""
    engine = open_database(str(tmp_path / "notes.db"), create=True)
    create_study(engine, parse_design(NOTES_DESIGN), NOTES_DESIGN)
    add_participant(engine, "novice")
    try:
        yield engine
    finally:
        engine.dispose()


async def test_a_notes_trial_shows_the_scope_and_stores_its_samples(
    notes_engine: Engine, tmp_path: Path
) -> None:
    services = StudyServices(notes_engine, load_estimator)
    app = make_app(services, TuiSettings(simulated_pace=None, figures_dir=tmp_path / "f"))
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _start(pilot, "P001")
        await wait_for(pilot, lambda: pane.status == "completed", 120)
        # the NOTES view, not the LCCA phantom, was shown and fed
        view = app.query_one(NotesView)
        assert view.display
        assert not app.query_one(PhantomView).display
        assert view._frame is not None
        assert view._frame.task.name == "notes"
        assert app.query_one("#phantom-box").border_title == "NOTES: scope depth and roll"
        # the trial's line (the block's summary, of this one trial, repeats it)
        shown = next(
            line
            for line in pane.last_outcome.split("\n")
            if line.startswith("  peak demanded force ")
        )
        text = shown.split()[3]
        peak = float(text)
        # half a unit of the last digit shown (three significant figures)
        shown_to = 0.5 * 10.0 ** -(len(text.split(".")[1]) if "." in text else 0)
        # the block's summary in the readout beside the scene (the form opened for the
        # block: back to F3): every NOTES measure, the last one inside the box's height
        await pilot.press("f3")
        await pilot.pause(0.3)
        rows = screen_text(app).splitlines()
        box = app.query_one("#phantom-box").region
        beside = [r[box.right :].strip() for r in rows[box.y : box.bottom]]
        summary = beside[beside.index(f"block notes/{trial_condition(notes_engine)} done:") :]
        labels = [m.label for m in get_task("notes").all_measures]
        summary = summary[: summary.index("")]
        assert len(summary) == 2 + len(labels)
        assert all(
            line.startswith(f"{label} ") for line, label in zip(summary[2:], labels, strict=True)
        )
        assert beside[-1] == ""  # the row of the box's bottom border
    with Session(notes_engine) as session:
        trial = session.scalars(select(Trial)).one()
        n = session.scalar(select(func.coalesce(func.sum(SampleChunk.n_samples), 0)))
    assert (trial.task, trial.status, trial.driver) == ("notes", "completed", "simulated")
    assert n == round(trial.completion_time_s * 100)
    # the peak shown is the stored one (the demanded force, as `study run` stores it)
    assert peak == pytest.approx(
        trial.measure_values["peak_force_demanded_n"], abs=shown_to * (1 + 1e-9)
    )


async def test_the_keyboard_drives_a_notes_trial(notes_engine: Engine, tmp_path: Path) -> None:
    services = StudyServices(notes_engine, load_estimator)
    app = make_app(services, TuiSettings(figures_dir=tmp_path / "f"))
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _start(pilot, "P001", "d")  # d: the keyboard drives
        await wait_for(pilot, lambda: pane.run is not None and pane.run.live.batches > 2, 120)
        await pilot.press("up", "up", "up", "right")
        # the aim of 3 steps sets an insertion speed, so the scope goes in and rolls
        await wait_for(pilot, lambda: pane.run.live.frame().insertion_m > 0.01, 30)
        await wait_for(pilot, lambda: pane.run.live.frame().rotation_rad > 0.01, 30)
        readout = str(app.query_one("#readout").render())
        assert "insertion-speed aim +" in readout
        assert "dial aim" not in readout
        # x holds it and asks why; Esc lets it go on, a reason stops it
        await pilot.press("x")
        await wait_for(pilot, lambda: isinstance(app.screen, StopScreen), 10)
        await pilot.press("escape")
        await pilot.pause(0.3)
        assert pane.run is not None
        assert pane.status == "running"
        await pilot.press("x")
        await wait_for(pilot, lambda: isinstance(app.screen, StopScreen), 10)
        await pilot.press(*"scope fogged", "enter")
        await wait_for(pilot, lambda: pane.status == "interrupted", 30)
    [(status, driver, samples)] = _trials(notes_engine)
    assert (status, driver) == ("interrupted", "keyboard")
    assert samples > 0
    with Session(notes_engine) as session:
        entry = session.scalars(select(AuditEntry).where(AuditEntry.entity == "trial")).one()
    assert (entry.old_value, entry.new_value) == ("running", "interrupted")
    assert entry.reason == f"{STOPPED_REASON}: scope fogged"


async def test_a_design_can_let_the_next_block_start_before_the_questionnaire(
    tmp_path: Path,
) -> None:
    from tests.study.tui.conftest import complete_block

    text = NOTES_DESIGN.replace(
        'tasks = ["notes"]', 'tasks = ["lcca"]\nbreak_s = 0\ntlx_before_next_block = false'
    )
    design = parse_design(text)
    assert design.tlx_before_next_block is False
    assert parse_design(NOTES_DESIGN).tlx_before_next_block  # on by default
    engine = open_database(str(tmp_path / "s.db"), create=True)
    create_study(engine, design, text)
    add_participant(engine, "novice")
    with Session(engine) as session:
        first = session.scalars(select(ScheduleBlock).order_by(ScheduleBlock.block_index)).first()
        task, condition = first.task, first.condition
    complete_block(engine, "P001", task, condition)
    app = make_app(StudyServices(engine, load_estimator), TuiSettings(figures_dir=tmp_path / "f"))
    try:
        async with app.run_test(size=(80, 24)) as pilot:
            pane = await run_screen(pilot, "P001")
            # the questionnaire is still listed as due, but it does not hold the next block
            assert pane.roster.tlx_due() == [("P001", task, condition)]
            label = str(app.query_one("#next", Label).render())
            assert label.startswith("next: P001 ")
            assert "due first" not in label
    finally:
        engine.dispose()
