"""The break after a block: its clock stands while the participant fills in the NASA-TLX
(the TLX screen open on their questionnaire), and the terminal bell rings once when it
ends."""

from __future__ import annotations

import time
from pathlib import Path

from db.migrate import open_database
from db.models.tlx import TLX_SUBSCALES
from study.protocol.design import parse_design
from study.protocol.roster import add_participant, create_study
from study.protocol.tlx import store_tlx
from study.tui import StudyServices, TuiSettings, make_app
from study.tui.run_pane import RunPane
from study.tui.trial_runner import TrialOutcome
from tests.study.tui.conftest import complete_block, run_screen, wait_for

BREAK_S = 3.0
DESIGN = f"""\
name = "break bell"
seed = 3
trials_per_condition = 1
practice_trials = 0
break_s = {BREAK_S:g}
[groups]
novice = 1
"""


async def test_the_break_stands_during_the_tlx_and_rings_when_it_ends(tmp_path: Path) -> None:
    engine = open_database(str(tmp_path / "study.db"), create=True)
    create_study(engine, parse_design(DESIGN), DESIGN)
    add_participant(engine, "novice")
    complete_block(engine, "P001", "lcca", "VO")
    settings = TuiSettings(prepare_simulation=False, figures_dir=tmp_path / "figures")
    app = make_app(StudyServices(engine, lambda: None), settings)
    rings: list[float] = []
    app.bell = lambda: rings.append(time.monotonic())  # type: ignore[method-assign]
    try:
        async with app.run_test(size=(80, 24)) as pilot:
            pane = await run_screen(pilot, "P001")
            # the block's last trial ends: the app opens its questionnaire
            outcome = TrialOutcome("P001", [1], 0, 1.0)
            pane.post_message(RunPane.TrialEnded(outcome, ("P001", "lcca", "VO")))
            await wait_for(pilot, lambda: "P001" in pane._breaks, 10)
            await wait_for(pilot, lambda: app.query_one("#tabs").active == "tlx", 10)
            # the clock runs until the form is open (on a loaded machine opening it can
            # take a while), then stands
            left_on_the_form = pane.break_left_s("P001")
            assert left_on_the_form > 0
            await pilot.pause(BREAK_S + 2.0)  # longer than the break, on the form
            assert rings == []
            # it stood (no bell above): the clock moves only between its 1 s ticks, each
            # of which credits the time on the form back (a tick may come late under load)
            assert pane.break_left_s("P001") >= left_on_the_form - 1.5
            store_tlx(engine, "P001", "lcca", "VO", dict.fromkeys(TLX_SUBSCALES, 50))
            saved = time.monotonic()
            app.reload()
            await wait_for(pilot, lambda: len(rings) == 1, BREAK_S + 5)
            assert rings[0] - saved > BREAK_S - 2.0  # the break ran after the form
            await pilot.pause(2.5)
            assert len(rings) == 1  # once
    finally:
        engine.dispose()
