"""A restart after a kill, the checklist asked once per participant, and the small things:
the picker's unknown code, the over-target fill, the dialogs' keys, the backup's mode."""

from __future__ import annotations

import os
import socket
import stat
import subprocess
import sys
from pathlib import Path

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session
from textual.widgets import DataTable, Label

from db.base import utcnow
from db.models.audit import AuditEntry
from db.models.lease import SessionLease
from db.models.study import Participant
from db.models.trial import Trial
from study.protocol.roster import add_participant
from study.protocol.session import TAKEN_OVER
from study.protocol.withdrawal import record_checklist
from study.tui.confirm import Confirm, ReasonScreen
from study.tui.overview import fill_text
from tests.study.tui.conftest import loaded, on_screen, run_screen, wait_for


def _running_trial(engine: Engine, code: str, pid: int) -> int:
    """A trial of `code` left `running` under a lease held by process `pid`."""
    with Session(engine) as session, session.begin():
        p = session.scalars(select(Participant).where(Participant.code == code)).one()
        block = p.blocks[0]
        trial = Trial(
            participant_id=p.id,
            block_id=block.id,
            task=block.task,
            condition=block.condition,
            block_index=block.block_index,
            trial_index=0,
            status="running",
            driver="simulated",
            started_at=utcnow(),
        )
        session.add(trial)
        session.add(
            SessionLease(
                participant_id=p.id,
                token=f"t{pid}",
                host=socket.gethostname(),
                pid=pid,
                acquired_at=utcnow(),
                heartbeat_at=utcnow(),
            )
        )
        session.flush()
        return trial.id


def _notices(app) -> list[str]:
    return [n.message for n in app._notifications]


async def test_a_trial_left_running_by_a_killed_app_is_marked_and_said_at_start(
    make_test_app, study_engine: Engine
) -> None:
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    pid = int(dead.stdout)
    killed = _running_trial(study_engine, "P001", pid)  # its process is gone
    alive = _running_trial(study_engine, "P002", os.getpid())  # a live session: not ours
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await wait_for(pilot, lambda: any("P001" in n for n in _notices(app)), 10)
        [line] = [n for n in _notices(app) if "P001" in n]
        assert line == (
            "P001: a trial was found running (the program running it had ended) and "
            "marked interrupted; it is repeated at the next start"
        )
        assert not any("P002" in n for n in _notices(app))
    with Session(study_engine) as session:
        assert session.get(Trial, killed).status == "interrupted"
        assert session.get(Trial, alive).status == "running"
        entry = session.scalars(
            select(AuditEntry).where(AuditEntry.entity == "trial", AuditEntry.entity_id == killed)
        ).one()
    # the dead process's lease, taken over: the reason says whose it was
    assert entry.reason == TAKEN_OVER.format(f"its process {pid} on {socket.gethostname()} is gone")


async def test_the_checklist_recorded_before_a_restart_is_not_asked_again(
    make_test_app, study_engine: Engine
) -> None:
    record_checklist(study_engine, "P001")  # confirmed in the app's last run
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        await pilot.press("s")
        # the trial starts (its estimator: this test's, which refuses) without the question
        await wait_for(pilot, lambda: pane.run is not None or pane.status != "idle", 10)
        assert not isinstance(app.screen, Confirm)
    with Session(study_engine) as session:
        n = session.scalar(
            select(func.count())
            .select_from(AuditEntry)
            .where(AuditEntry.field == "session_checklist")
        )
    assert n == 1


async def test_an_unknown_code_in_the_picker_says_so(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        await pilot.press("f3")
        await pilot.press("enter")  # nobody picked: the list has the focus, Enter opens it
        await wait_for(pilot, lambda: app.screen.query("#picker-search"), 10)
        await pilot.press(*"P099")
        await pilot.pause()
        keys = str(app.screen.query_one("#picker-keys", Label).render())
        assert keys.startswith("no participant P099 (codes P001...P002)")


def test_the_fill_bar_keeps_its_width_past_the_target() -> None:
    assert fill_text(2, 3) == "█" * 11 + "░" * 5  # round(16 * 2 / 3) = 11 cells
    assert fill_text(3, 3) == "█" * 16
    assert fill_text(4, 3) == "█" * 16 + " 4 of 3 (over target)"


async def test_the_overview_says_over_target(make_test_app, study_engine: Engine) -> None:
    for _ in range(2):
        add_participant(study_engine, "expert")  # 3 of 2
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        fill = app.query_one("#groups", DataTable).get_row("expert")[3]
        assert fill.endswith(" 3 of 2 (over target)")


async def test_the_export_and_backup_dialogs_say_what_enter_does(
    make_test_app, tmp_path: Path
) -> None:
    app = make_test_app(backups_dir=tmp_path / "backups", exports_dir=tmp_path / "exports")
    async with on_screen(app, "f1") as pilot:
        for key, says in (("e", "Enter: export there"), ("b", "Enter: check and back up there")):
            await pilot.press(key)
            await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
            keys = str(app.screen.query_one("#reason-keys", Label).render())
            assert keys == f"{says}    Esc: cancel"
            assert "record it" not in keys
            await pilot.press("escape")
            await pilot.pause()


def test_the_backup_file_is_readable_by_its_owner_only(
    study_engine: Engine, tmp_path: Path
) -> None:
    from db.maintenance import backup_database
    from teleop_core.files import replace_durably

    old = os.umask(0o022)  # a usual umask: files made 644 unless made otherwise
    try:
        result = backup_database(study_engine, tmp_path / "b", replace_file=replace_durably)
    finally:
        os.umask(old)
    assert result.copy.ok
    assert stat.S_IMODE(result.path.stat().st_mode) == 0o600


async def test_after_the_palettes_run_next_trial_p_and_d_act_at_once(
    make_test_app, study_engine: Engine
) -> None:
    from study.tui.run_pane import RunPane
    from tests.study.tui.conftest import complete_block

    with Session(study_engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == "P002")).one()
        first = min(p.blocks, key=lambda b: b.block_index)
        block = (first.task, first.condition)
    complete_block(study_engine, "P002", *block)  # its questionnaire comes first
    app = make_test_app(simulated_pace=None)
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        pane = app.query_one(RunPane)
        await pilot.press("ctrl+p")
        await pilot.press(*"Run the next trial of P002")
        await pilot.pause(0.5)
        await pilot.press("enter")
        await wait_for(pilot, lambda: any("NASA-TLX comes before" in n for n in _notices(app)))
        assert pane.run is None
        await pilot.press("p")
        assert pane.pace == 1.0  # as fast as it goes -> 1x: the key acted, no Esc first
        await pilot.press("d")
        assert pane.driver_kind == "keyboard"
