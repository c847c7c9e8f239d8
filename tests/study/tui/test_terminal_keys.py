"""The real `study tui` at 80 x 24 in a pseudo-terminal: `--pace 8` and p, a note on a
read-only database, a lock during a trial, e on a measured trial, the NOTES key hints,
and every tab and the help key at 60 x 20."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.trial import SampleChunk, Trial
from tests.study.tui import test_terminal_db_errors as terminal
from tests.study.tui.test_run_session import NOTES_DESIGN
from tests.study.tui.test_terminal_db_errors import F2, App, words

# the fixtures of the database-error terminal tests, used here too
study_file = terminal.study_file
read_only_study = terminal.read_only_study

F3, F4 = "\x1bOR", "\x1bOS"
DOWN = "\x1b[B"


def _pick_first(app: App) -> None:
    """F3, then the participant list by keys: Enter (F3 focuses it), down, Enter (P001)."""
    app.child.send(F3)
    app.child.expect("driver:")
    time.sleep(1.0)  # the screen takes the focus
    app.child.send("\r")
    app.child.expect("P001")  # the list is open
    app.child.send(DOWN)
    time.sleep(0.5)
    app.child.send("\r")
    app.child.expect(words("next:", "P001"))


def _trial(db: Path) -> tuple[str, bool | None, int]:
    engine = open_database(str(db), create=False)
    try:
        with Session(engine) as session:
            trial = session.scalars(select(Trial)).one()
            n = session.scalar(select(func.coalesce(func.sum(SampleChunk.n_samples), 0)))
            return trial.status, trial.success, round(trial.completion_time_s * 100) - n
    finally:
        engine.dispose()


def test_p_after_starting_at_pace_8(study_file: Path) -> None:
    app = App(str(study_file), study_file.parent, args=["--pace", "8"])
    try:
        app.loaded()
        _pick_first(app)
        app.child.send("p")
        app.child.expect(words("pace:", "1x"))
        assert app.child.isalive()
        app.quit()
    finally:
        app.close()


def test_a_note_refused_by_a_read_only_database_is_kept(
    read_only_study: tuple[Path, list[str]],
) -> None:
    db, prefix = read_only_study
    app = App(str(db), db.parent, prefix, env={"HOME": str(db.parent)})
    try:
        app.loaded()
        app.child.send(F2)
        app.child.expect("Session note")
        app.child.send("\x0f")  # ctrl+o
        app.child.expect(words("contact", "details"))
        app.child.send("dial recalibrated\r")
        app.child.expect(words("note", "not", "kept:", "the", "database", "is", "read-only"))
        assert "not withdrawn" not in app.drawn.getvalue()
        app.child.expect("dial recalibrated")  # the dialog again, the note as typed
        app.child.send("\x1b")
        app.still_answers()
        app.quit()
    finally:
        app.close()


def test_a_lock_during_a_trial_is_shown_and_nothing_is_lost(study_file: Path) -> None:
    from tests.db.test_samples_lock import Locker

    app = App(str(study_file), study_file.parent)
    try:
        app.loaded()
        _pick_first(app)
        app.child.send("s")
        app.child.expect("consent confirmed")
        app.child.send("y")
        app.child.expect(words("running:", "P001"), timeout=240)  # loads the estimator
        app.child.expect(r"t +[1-9]\.\d s")  # a second of the trial has run
        locker = Locker(str(study_file))  # another program takes the lock
        app.child.expect(words("waiting", "for", "the", "database"), timeout=60)
        app.child.expect(r"t +\d+\.\d s")  # the live view goes on meanwhile
        locker.release()
        # the block is done: the app opens its questionnaire
        app.child.expect(words("How", "mentally", "demanding"), timeout=120)
        assert "free space" not in app.drawn.getvalue()
        app.quit()
    finally:
        app.close()
    status, _, missing = _trial(study_file)
    assert (status, missing) == ("completed", 0)


def test_e_asks_before_ending_a_measured_trial(study_file: Path) -> None:
    app = App(str(study_file), study_file.parent)
    try:
        app.loaded()
        _pick_first(app)
        app.child.send("d")  # the keyboard drives
        app.child.expect(words("driver:", "keyboard"))
        app.child.send("s")
        app.child.expect("consent confirmed")
        app.child.send("y")
        app.child.expect(words("running:", "P001"), timeout=240)  # loads the estimator
        app.child.send("e")
        app.child.expect(words("measured", "trial", "now?"))
        app.child.send("y")
        # the block is done: the app opens its questionnaire
        app.child.expect(words("How", "mentally", "demanding"), timeout=60)
        app.quit()
    finally:
        app.close()
    status, success, _ = _trial(study_file)
    assert (status, success) == ("completed", False)


@pytest.fixture
def notes_file(tmp_path: Path) -> Iterator[Path]:
    from study.protocol.design import parse_design
    from study.protocol.roster import add_participant, create_study

    db = tmp_path / "notes.db"
    engine: Engine = open_database(str(db), create=True)
    create_study(engine, parse_design(NOTES_DESIGN), NOTES_DESIGN)
    add_participant(engine, "novice")
    engine.dispose()
    yield db


def test_the_notes_key_hints_are_whole_at_80x24(notes_file: Path) -> None:
    app = App(str(notes_file), notes_file.parent)
    try:
        app.loaded()
        _pick_first(app)
        app.child.send("d")
        app.child.send("s")
        app.child.expect("consent confirmed")
        app.child.send("y")
        app.child.expect(words("let", "go", "e", "end"), timeout=240)
        app.child.send("x")
        app.child.expect(r"Stop P001")
        app.child.send("tired\r")
        app.child.expect("interrupted")
        app.quit()
    finally:
        app.close()


def test_every_tab_and_the_help_key_at_60x20(study_file: Path) -> None:
    app = App(str(study_file), study_file.parent, env={"COLUMNS": "60", "LINES": "20"})
    try:
        app.child.setwinsize(20, 60)
        # in whatever order the terminal receives them
        wanted = [words("F1", "Home"), words("F6", "Calib"), words("?", "Help")]
        seen: set[int] = set()
        while len(seen) < len(wanted):
            seen.add(app.child.expect(wanted))
        app.quit()
    finally:
        app.close()
