"""Fixtures of the terminal app's tests: a small study database and the app over it."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import Engine
from textual.widgets import Input

from db.migrate import open_database
from study.protocol.design import parse_design
from study.protocol.roster import add_participant, create_study
from study.tui import StudyApp, StudyServices, TuiSettings, make_app

DESIGN = """\
name = "tui test"
seed = 3
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 2
expert = 2
"""
"""Two groups of two, one measured trial per block: a trial ends a block."""


@pytest.fixture(autouse=True)
def no_cursor_blink(monkeypatch: pytest.MonkeyPatch) -> None:
    """A blinking cursor makes screenshots depend on the moment they are taken."""
    original = Input.__init__

    def init(self: Input, *args: object, **kwargs: object) -> None:
        original(self, *args, **kwargs)  # type: ignore[arg-type]
        self.cursor_blink = False

    monkeypatch.setattr(Input, "__init__", init)


@pytest.fixture(autouse=True)
def own_settings_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`study tui` remembers d and p in the user's settings file: each test its own."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))


@pytest.fixture
def study_engine(tmp_path: Path) -> Iterator[Engine]:
    """A study with P001 (novice) and P002 (expert) enrolled, nothing run."""
    engine = open_database(str(tmp_path / "study.db"), create=True)
    create_study(engine, parse_design(DESIGN), DESIGN)
    add_participant(engine, "novice")
    add_participant(engine, "expert")
    try:
        yield engine
    finally:
        engine.dispose()


def _no_estimator() -> object:
    raise AssertionError("this test runs no trial")


@pytest.fixture
def make_test_app(study_engine: Engine, tmp_path: Path) -> Callable[..., StudyApp]:
    """make_app over the study, with no simulation prepared unless a test asks for it."""

    def build(load_estimator=_no_estimator, calibrate=None, **settings) -> StudyApp:
        settings.setdefault("prepare_simulation", False)
        settings.setdefault("figures_dir", tmp_path / "figures")
        settings.setdefault("calibrations_dir", tmp_path / "calibrations")
        services = StudyServices(study_engine, load_estimator, calibrate)
        return make_app(services, TuiSettings(**settings))

    return build


async def wait_for(pilot, condition: Callable[[], bool], timeout_s: float = 60.0) -> None:
    """Let the app run until `condition()` holds (workers finish); fail after timeout_s."""
    end = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"condition not reached in {timeout_s} s")
        await pilot.pause(0.05)


def screen_text(app: StudyApp) -> str:
    """The app's screen as the terminal shows it, one line a row (what `tmux
    capture-pane -p` gives), for asserting that nothing is cut."""
    import io

    from rich.console import Console

    width, height = app.size
    console = Console(width=width, height=height, file=io.StringIO(), record=True)
    console.print(app.screen._compositor.render_update(full=True))
    return console.export_text()


async def loaded(pilot) -> None:
    await wait_for(pilot, lambda: pilot.app.ready and pilot.app.roster is not None)


async def tlx_form(pilot, block: tuple[str, str, str] = ("P001", "lcca", "VO")) -> Any:
    """F4 with `block` (participant, task, condition) open on the NASA-TLX form, once the
    app has loaded; the form's pane."""
    from study.tui.tlx_pane import TlxPane

    await loaded(pilot)
    await pilot.press("f4")
    pane = pilot.app.query_one(TlxPane)
    pane.open_block(*block)
    await wait_for(pilot, lambda: pane.loaded_block == block, 10)
    return pane


async def run_screen(pilot, code: str) -> Any:
    """The run screen (F3) with participant `code` picked, once the app has loaded."""
    from study.tui.run_pane import RunPane

    await loaded(pilot)
    await pilot.press("f3")
    pane = pilot.app.query_one(RunPane)
    pane.select_participant(code)
    await pilot.pause()
    return pane


@asynccontextmanager
async def on_screen(app: StudyApp, key: str) -> AsyncIterator[Any]:
    """`app` headless on an 80 x 24 terminal, loaded, with the screen of `key` open: the
    pilot."""
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press(key)
        yield pilot


async def analysed(pilot) -> Any:
    """Open the analysis screen (f5), run the analysis (r) and wait for its result;
    return the analysis pane."""
    await loaded(pilot)
    await pilot.press("f5", "r")
    pane = pilot.app.query_one("#analysis-pane")
    await wait_for(pilot, lambda: pane.result is not None)
    return pane


PEAKS = {  # (group, condition) -> peak proximal force of each participant's trial, N
    ("novice", "VO"): (1.0, 1.2, 1.4),
    ("novice", "HV"): (0.5, 0.6, 0.7),
    ("expert", "VO"): (0.8, 0.9, 1.0),
    ("expert", "HV"): (0.4, 0.5, 0.9),
}


def store_trials(engine: Engine) -> None:
    """Three participants per group with one completed trial per condition (and a few
    samples each, which the force-trace figure draws)."""
    from sqlalchemy import select
    from sqlalchemy.orm import Session

    from db.models.study import Participant
    from db.models.trial import Trial
    from db.samples import SampleWriter
    from study.protocol.tasks import get_task

    for _ in range(2):
        add_participant(engine, "novice")
        add_participant(engine, "expert")
    with Session(engine) as session:
        people = session.scalars(select(Participant).order_by(Participant.code)).all()
        counts = dict.fromkeys(PEAKS, 0)
        for p in people:
            for block in p.blocks:
                k = counts[(p.group, block.condition)]
                counts[(p.group, block.condition)] += 1
                peak = PEAKS[(p.group, block.condition)][k]
                session.add(
                    Trial(
                        participant_id=p.id,
                        block_id=block.id,
                        task="lcca",
                        condition=block.condition,
                        block_index=block.block_index,
                        trial_index=0,
                        status="completed",
                        completion_time_s=20.0 + 10 * peak,
                        success=True,
                        driver="simulated",
                        measure_values={
                            "peak_proximal_force_n": peak,
                            "peak_distal_force_n": peak / 2,
                            "wall_contacts": 0,
                        },
                    )
                )
        session.commit()
        ids = session.scalars(select(Trial.id)).all()
    for trial_id in ids:
        with SampleWriter(engine, trial_id, schema=get_task("lcca").sample_schema()) as out:
            force = [0.1, 0.2]
            out.extend(
                {
                    "t_s": [0.0, 0.01],
                    "reference_force_n": force,
                    "proximal_force_n": force,
                    "distal_force_n": [0.0, 0.1],
                }
            )


def complete_block(engine: Engine, code: str, task: str, condition: str) -> None:
    """One completed (simulated) trial in `code`'s `task`/`condition` block, so that the
    block has run and its questionnaire can be stored without a reason."""
    from sqlalchemy import select
    from sqlalchemy.orm import Session

    from db.models.study import Participant
    from db.models.trial import Trial

    with Session(engine) as session, session.begin():
        p = session.scalars(select(Participant).where(Participant.code == code)).one()
        block = next(b for b in p.blocks if (b.task, b.condition) == (task, condition))
        session.add(
            Trial(
                participant_id=p.id,
                block_id=block.id,
                task=task,
                condition=condition,
                block_index=block.block_index,
                trial_index=0,
                status="completed",
                completion_time_s=30.0,
                success=True,
                driver="simulated",
                measure_values={
                    "peak_proximal_force_n": 0.5,
                    "peak_distal_force_n": 0.2,
                    "wall_contacts": 0,
                },
            )
        )
