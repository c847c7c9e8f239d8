"""A restart of the app: a trial a killed session left running is named at start, and
the session checklist recorded before is not asked again."""

from __future__ import annotations

import socket
import subprocess

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.base import utcnow
from db.models.lease import SessionLease
from db.models.study import Participant
from db.models.trial import Trial
from study.protocol.withdrawal import record_checklist
from study.tui.confirm import Confirm
from tests.study.tui.conftest import loaded, run_screen, wait_for


def _left_running_by_a_killed_process(engine, code: str) -> None:
    """`code`'s first trial `running` and their lease held by a process that is gone,
    as `kill -9` of the app leaves them."""
    gone = subprocess.Popen(["true"])
    gone.wait()  # its pid is no process's any more
    with Session(engine) as session:
        participant = session.scalars(select(Participant).where(Participant.code == code)).one()
        block = min(participant.blocks, key=lambda b: b.block_index)
        now = utcnow()
        session.add(
            Trial(
                participant_id=participant.id,
                block_id=block.id,
                task=block.task,
                condition=block.condition,
                block_index=block.block_index,
                trial_index=0,
                driver="simulated",
                status="running",
                started_at=now,
            )
        )
        session.add(
            SessionLease(
                participant_id=participant.id,
                token="killed",
                host=socket.gethostname(),
                pid=gone.pid,
                acquired_at=now,
                heartbeat_at=now,
            )
        )
        session.commit()


def _notices(app) -> list[str]:
    return [str(n.message) for n in app._notifications]


async def test_a_trial_a_killed_session_left_running_is_named_at_start(
    make_test_app, study_engine
) -> None:
    _left_running_by_a_killed_process(study_engine, "P002")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await wait_for(pilot, lambda: any("P002: a trial" in n for n in _notices(app)), 10)
        [notice] = [n for n in _notices(app) if n.startswith("P002")]
        assert "found running from a session that has ended" in notice
        assert "counts as interrupted and is repeated" in notice
        assert not any(n.startswith("P001") for n in _notices(app))


async def test_no_notice_when_nothing_was_left_running(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.pause(0.5)
        assert not any("found running" in n for n in _notices(app))


async def test_the_checklist_recorded_before_a_restart_is_not_asked_again(
    make_test_app, study_engine
) -> None:
    record_checklist(study_engine, "P001")  # confirmed at an earlier start of the app
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P002")
        await pilot.press("s")  # P002 has none recorded: asked
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        assert "Session checklist for P002" in str(app.screen.query_one("#question").render())
        await pilot.press("n")
        pane.select_participant("P001")
        await pilot.pause()
        await pilot.press("s")  # P001's is recorded: the trial starts without it
        await wait_for(pilot, lambda: pane.run is not None, 10)
        assert not isinstance(app.screen, Confirm)
