"""The run screen honours the design's `[lsl]` table: one marker stream for the app's
life, carrying each trial run from the screen (the suite's loopback-only liblsl config,
tests/conftest.py; a marker inlet written here, as a lab's recorder)."""

from __future__ import annotations

import uuid
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.trial import Trial
from study.lsl.markers import parse
from study.protocol.default_estimator import load_estimator
from study.protocol.design import parse_design
from study.protocol.roster import add_participant, create_study
from study.tui import StudyServices, TuiSettings, make_app
from study.tui.confirm import Confirm
from tests.study.lsl.test_session_streams import MarkerInlet
from tests.study.tui.conftest import run_screen, wait_for

DESIGN = """\
name = "tui lsl {tag}"
seed = 6
tasks = ["lcca"]
trials_per_condition = 2
practice_trials = 0
[groups]
novice = 1
[lsl]
publish = true
"""


async def test_trials_run_from_the_screen_send_their_markers_on_one_stream(
    tmp_path: Path,
) -> None:
    tag = uuid.uuid4().hex[:8]
    design = DESIGN.format(tag=tag)
    engine = open_database(str(tmp_path / "lsl.db"), create=True)
    create_study(engine, parse_design(design), design)
    add_participant(engine, "novice")
    listener = MarkerInlet(f"haptic-study/tui lsl {tag}/P001")
    listener.start()
    app = make_app(
        StudyServices(engine, load_estimator),
        TuiSettings(simulated_pace=None, figures_dir=tmp_path / "f"),
    )
    try:
        async with app.run_test(size=(80, 24)) as pilot:
            pane = await run_screen(pilot, "P001")
            await pilot.press("s")
            await wait_for(pilot, lambda: isinstance(pilot.app.screen, Confirm), 10)
            await pilot.press("y")  # the session checklist
            await wait_for(pilot, lambda: pane.status == "completed", 120)
            # the streams stay open after the trial: a recorder subscribes meanwhile
            await wait_for(pilot, listener.connected.is_set, 30)
            await pilot.press("s")
            await wait_for(pilot, lambda: pane.status == "completed" and pane.run is None, 120)
            await wait_for(pilot, lambda: len(listener.markers) >= 2, 10)
            assert listener.is_alive()  # no session_end while the app runs
        # the app has quit: its streams end
        listener.join(timeout=30)
        assert not listener.is_alive()
        with Session(engine) as s:
            trials = s.scalars(select(Trial).order_by(Trial.id)).all()
            rows = [
                (t.id, t.task, t.condition, t.block_index, t.trial_index, t.success) for t in trials
            ]
    finally:
        engine.dispose()
    assert len(rows) == 2
    markers = [parse(text) for _, text in listener.markers]
    second = rows[1]
    # the second trial on the stream opened for the first, then the stream's end
    assert [m["event"] for m in markers[-3:]] == ["trial_start", "trial_end", "session_end"]
    assert "session_start" not in [m["event"] for m in markers]  # one session, opened before
    for m in markers[-3:-1]:
        got = (m["trial_id"], m["task"], m["condition"], m["block"], m["trial"])
        assert got == second[:5]
        assert (m["participant"], m["group"], m["study"]) == ("P001", "novice", f"tui lsl {tag}")
    assert markers[-2]["status"] == "completed"
    assert markers[-2]["success"] == second[5]


def test_the_lsl_flag_publishes_for_a_design_without_the_table(study_engine) -> None:
    """`study tui --lsl` (`lsl_publish`) as `study run --lsl`; neither: no observer."""
    assert StudyServices(study_engine, load_estimator).lsl_observer() is None
    services = StudyServices(study_engine, load_estimator, lsl_publish=True)
    observer = services.lsl_observer()
    assert observer is not None
    assert services.lsl_observer() is observer
    services.close_lsl()
