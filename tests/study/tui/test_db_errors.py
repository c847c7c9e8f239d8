"""The app never ends on a database error: a read-only or locked database gives one
plain line, the screen stays, and what was typed is kept.

The database is a real SQLite file made read-only per connection (`PRAGMA query_only`:
the tests run as root, for whom file permissions do not stop a write) or write-locked by
a second connection holding `BEGIN EXCLUSIVE`, as another program would.
"""

from __future__ import annotations

import sqlite3
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager, contextmanager

import pytest
from sqlalchemy import Engine, event, func, insert, select
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session
from textual.widgets import Input

from db.models.audit import AuditEntry
from db.models.study import Participant
from study.protocol.tlx import load_tlx
from study.tui.db_errors import plain_line
from study.tui.tlx_pane import PairChoice
from tests.study.tui.conftest import complete_block, loaded, wait_for
from tests.study.tui.test_screens import RATINGS, _open_form, _type_ratings


@contextmanager
def pragma(engine: Engine, statement: str) -> Iterator[None]:
    """Every new connection of `engine` runs `statement` (the pool is emptied first)."""

    def on_connect(dbapi_connection, _record) -> None:  # type: ignore[no-untyped-def]
        dbapi_connection.execute(statement)

    engine.dispose()
    event.listen(engine, "connect", on_connect)
    try:
        yield
    finally:
        event.remove(engine, "connect", on_connect)
        engine.dispose()


@asynccontextmanager
async def participants_pane(app) -> AsyncIterator[tuple]:
    """`app` running on an 80 x 24 screen, loaded: (its pilot, its participants pane)."""
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        yield pilot, app.query_one("#participants-pane")


async def _enrol_refused(pilot, pane) -> None:
    """Press F2 then ctrl+a (enrol one) and wait for the pane to say it was not enrolled."""
    await pilot.press("f2")
    await pilot.press("ctrl+a")
    await wait_for(pilot, lambda: pane.last_message.startswith("not enrolled"), 30)


def _participants(engine: Engine) -> int:
    with Session(engine) as session:
        return session.scalar(select(func.count()).select_from(Participant)) or 0


def test_a_real_read_only_error_reads_as_one_plain_line(study_engine: Engine) -> None:
    with pragma(study_engine, "PRAGMA query_only = 1"), study_engine.begin() as conn:
        with pytest.raises(OperationalError) as caught:
            conn.execute(insert(Participant).values(code="P900", group="novice"))
    line = plain_line(caught.value)
    assert line.startswith("the database is read-only: nothing was written")
    assert "INSERT" not in line
    assert "\n" not in line
    assert "sqlalche.me" not in line
    assert "INSERT" in str(caught.value)  # what SQLAlchemy itself would have shown


async def test_enrolling_on_a_read_only_database_says_so_and_the_app_stays(
    make_test_app, study_engine: Engine
) -> None:
    app = make_test_app()
    async with participants_pane(app) as (pilot, pane):
        with pragma(study_engine, "PRAGMA query_only = 1"):
            await _enrol_refused(pilot, pane)
            assert pane.last_message.startswith("not enrolled: the database is read-only")
            assert app.is_running
        # writable again: the same key enrols, the app never left
        await pilot.press("ctrl+a")
        await wait_for(pilot, lambda: pane.last_message.startswith("enrolled P003"), 30)
    assert _participants(study_engine) == 3


async def test_enrolling_while_another_program_holds_the_lock_says_so(
    make_test_app, study_engine: Engine, tmp_path
) -> None:
    app = make_test_app()
    async with participants_pane(app) as (pilot, pane):
        other = sqlite3.connect(tmp_path / "study.db", isolation_level=None)
        other.execute("BEGIN EXCLUSIVE")
        try:
            with pragma(study_engine, "PRAGMA busy_timeout = 300"):
                await _enrol_refused(pilot, pane)
                assert "locked by another program" in pane.last_message
                assert app.is_running
        finally:
            other.execute("ROLLBACK")
            other.close()
    assert _participants(study_engine) == 2


async def test_a_questionnaire_refused_by_a_read_only_database_keeps_what_was_typed(
    make_test_app, study_engine: Engine
) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _open_form(pilot)
        await _type_ratings(pilot, RATINGS)
        for k, pair in enumerate(app.query(PairChoice)):
            pair.action_pick(k % 2)
        with pragma(study_engine, "PRAGMA query_only = 1"):
            await pilot.press("ctrl+s")
            await wait_for(pilot, lambda: pane.status.startswith("refused"), 30)
            assert pane.status.startswith("refused: the database is read-only")
            assert pane.status.endswith("the form keeps what was typed")
            assert app.is_running
        typed = {s: app.query_one(f"#rating-{s}", Input).value for s in RATINGS}
        assert typed == RATINGS
        assert load_tlx(study_engine, "P001", "lcca", "VO") is None
        await pilot.press("ctrl+s")  # the database is writable again: the same form saves
        await wait_for(pilot, lambda: pane.status == "P001 lcca/VO: stored", 30)
    stored = load_tlx(study_engine, "P001", "lcca", "VO")
    assert stored is not None
    assert stored.mental == int(RATINGS["mental"])


async def test_a_database_file_removed_mid_session_is_named_and_the_app_stays(
    make_test_app, study_engine: Engine, tmp_path
) -> None:
    # an open SQLite connection would go on committing into the deleted file (and a new
    # one would create an empty study.db): the enrolment is refused with one line
    app = make_test_app()
    async with participants_pane(app) as (pilot, pane):
        for name in ("study.db", "study.db-wal", "study.db-shm"):
            (tmp_path / name).unlink(missing_ok=True)
        await _enrol_refused(pilot, pane)
        db = tmp_path / "study.db"
        assert pane.last_message == (
            f"not enrolled: the study database file {db} is gone (deleted or moved?): "
            "nothing was written; put it back there and restart"
        )
        await pilot.pause()
        status, table = pane.query_one("#add-status"), pane.query_one("#people")
        # the whole line is on the screen at 80 columns: it wraps, the list moves down
        assert status.region.height > 1
        assert table.region.y > status.region.bottom
        await pilot.press("f1")
        await pilot.press("f2")
        assert app.is_running
        assert app.screen.query_one("#participants-pane") is pane
    assert not db.exists()  # no empty database was created in its place


def test_a_real_full_disk_reads_as_one_plain_line(tmp_path) -> None:
    # SQLite's own SQLITE_FULL: the file may not grow past the pages it has
    from sqlalchemy import create_engine, text

    engine = create_engine(f"sqlite:///{tmp_path / 'full.db'}")
    with pytest.raises(OperationalError) as caught, engine.begin() as conn:
        conn.execute(text("CREATE TABLE t (x TEXT)"))
        pages = conn.execute(text("PRAGMA page_count")).scalar()
        conn.execute(text(f"PRAGMA max_page_count = {pages}"))
        for _ in range(1000):
            conn.execute(text("INSERT INTO t VALUES (:x)"), {"x": "x" * 200})
    engine.dispose()
    assert "database or disk is full" in str(caught.value)
    line = plain_line(caught.value)
    assert line.startswith("the disk holding the database is full: nothing more was written")
    assert "\n" not in line
    assert "INSERT" not in line


@pytest.mark.postgres
def test_a_real_lost_server_connection_reads_as_one_plain_line(pg_url: str) -> None:
    # the server ends the session (as a restart or a dropped network would)
    from sqlalchemy import create_engine, text

    engine = create_engine(pg_url, pool_pre_ping=False)
    killer = create_engine(pg_url)
    with engine.connect() as conn:
        pid = conn.execute(text("SELECT pg_backend_pid()")).scalar()
        with killer.begin() as other:
            other.execute(text("SELECT pg_terminate_backend(:pid)"), {"pid": pid})
        with pytest.raises(OperationalError) as caught:
            conn.execute(text("SELECT 1"))
    engine.dispose()
    killer.dispose()
    line = plain_line(caught.value)
    assert line.startswith("the database server cannot be reached: nothing was written"), line
    assert "\n" not in line


async def test_a_note_refused_by_a_read_only_database_is_kept_for_the_next_try(
    make_test_app, study_engine: Engine
) -> None:
    from study.tui.confirm import ReasonScreen

    app = make_test_app()
    async with participants_pane(app) as (pilot, pane):
        await pilot.press("f2")
        table = app.query_one("#people")
        table.focus()
        with pragma(study_engine, "PRAGMA query_only = 1"):
            await pilot.press("ctrl+o")
            await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
            await pilot.press(*"dial recalibrated", "enter")
            await wait_for(pilot, lambda: pane.last_message.startswith("note not kept"), 30)
            # it names the note, not a withdrawal, and the read-only cause
            assert "withdrawn" not in pane.last_message
            assert "the database is read-only" in pane.last_message
            # the dialog is open again, holding the note as it was typed
            await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
            assert app.screen.query_one("#reason-text", Input).value == "dial recalibrated"
        # writable again: Enter keeps it
        await pilot.press("enter")
        await wait_for(pilot, lambda: pane.last_message == "P001: session note kept", 30)
    with Session(study_engine) as session:
        notes = session.scalars(
            select(AuditEntry.new_value).where(AuditEntry.field == "session_note")
        ).all()
    assert notes == ["dial recalibrated"]
