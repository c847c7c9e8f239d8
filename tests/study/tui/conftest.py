"""Fixtures of the terminal app's tests: a small study database and the app over it."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

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


async def loaded(pilot) -> None:
    await wait_for(pilot, lambda: pilot.app.ready and pilot.app.roster is not None)


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
        session.add(Trial(
            participant_id=p.id, block_id=block.id, task=task, condition=condition,
            block_index=block.block_index, trial_index=0, status="completed",
            completion_time_s=30.0, success=True, driver="simulated",
            measure_values={"peak_proximal_force_n": 0.5, "peak_distal_force_n": 0.2,
                            "wall_contacts": 0},
        ))  # fmt: skip
