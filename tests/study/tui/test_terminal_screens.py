"""The real `study tui` in tmux, the screen read as it is drawn: at 80 x 24 every key
hint of every screen is whole on the footer (and the task's keys on the run screen
during a keyboard trial, NOTES's `e end` too); during a trial neither start, driver nor
pace is offered and p changes nothing; at 60 x 20 the tab bar keeps all six tabs and the
footer its `? Help`. The pexpect tests of test_terminal_keys.py match the stream of
drawing; these read the whole screen, so a hint cut at the edge fails them."""

from __future__ import annotations

import shutil
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import Engine

from study.tui.analysis_pane import AnalysisPane
from study.tui.calibration_pane import CalibrationPane
from study.tui.participants import ParticipantsPane
from study.tui.run_pane import RunPane
from study.tui.task_views import live_view
from study.tui.tlx_pane import TlxPane
from tests.study.tui.lab_day import Terminal

pytestmark = pytest.mark.skipif(shutil.which("tmux") is None, reason="needs tmux")

QUIT, HELP = "^q Quit", "? Help"
SHOWN = {"F1": r"Sessions done", "F2": r"Find ", "F3": r"driver: ", "F5": r"Export"}
"""Text on each screen (and on no other) that says it is the one shown."""


def _hints(pane: type, hidden: tuple[str, ...] = ()) -> list[str]:
    """The footer's text for each binding `pane` shows (`hidden`: actions not offered
    now), as Textual draws it: ctrl+s as ^s."""
    return [
        f"{b.key.replace('ctrl+', '^')} {b.description}"
        for b in pane.BINDINGS
        if b.show and b.action not in hidden
    ]


def _footer(term: Terminal) -> str:
    return term.screen().rstrip("\n").splitlines()[-1]


def _start(db: Path, *args: str, size: tuple[int, int] = (80, 24)) -> Terminal:
    study = Path(sys.executable).with_name("study")
    term = Terminal([str(study), "tui", "--db", str(db), *args], db.parent, size=size)
    term.wait(r"Sessions done", 60)
    # the other screens are mounted after the overview shows: F2 acts once they are
    term.until(r"a Enrol", "F2", tries=60)
    term.keys("F1")
    term.wait(r"Sessions done")
    return term


def _quit(term: Terminal) -> None:
    term.keys("C-q")
    status = term.wait(r"^exit status: (\d+)", 60, where="history")
    history = term.history()
    assert "Traceback" not in history, history
    assert status.group(1) == "0", history


def _pick_first(term: Terminal) -> None:
    """F3 and P001 from the participant list (F3 focuses it while nobody is picked)."""
    term.keys("F3")
    term.wait(r"s Start")
    term.until(r"Enter: pick", "Enter")  # the picker: "(no change)", then P001...
    term.keys("Down", "Enter")
    term.wait(r"next: P001 ")


@pytest.fixture
def terminal(study_engine: Engine) -> Iterator[Path]:
    db = Path(study_engine.url.database)
    yield db


def test_every_key_hint_on_every_screen_at_80x24(terminal: Path) -> None:
    term = _start(terminal)
    try:
        screens = [
            ("F1", r"Sessions done", [QUIT, HELP]),
            ("F2", r"Find ", [*_hints(ParticipantsPane), QUIT, HELP]),
            ("F4", r"Which contributed more", [*_hints(TlxPane), QUIT, HELP]),
            ("F5", r"Analys", [*_hints(AnalysisPane), QUIT, HELP]),
            # its first field (the recording's path) takes `?` as text
            ("F6", r"Calibrat", [*_hints(CalibrationPane), QUIT]),
        ]
        for key, shown, hints in screens:
            term.keys(key)
            term.wait(shown)
            term.wait(hints[0].replace("^", r"\^"))
            footer = _footer(term)
            for hint in hints:
                assert hint in footer, (key, hint, footer)
            assert footer.rstrip().endswith("^p palette"), (key, footer)
        _pick_first(term)
        term.wait(r"s Start d Driver")
        footer = _footer(term)
        for hint in [*_hints(RunPane, hidden=("stop",)), QUIT, HELP]:
            assert hint in footer, ("F3", hint, footer)
        _quit(term)
    finally:
        term.close()


def test_no_start_driver_or_pace_during_a_trial_and_p_changes_nothing(terminal: Path) -> None:
    term = _start(terminal, "--pace", "1")
    try:
        _pick_first(term)
        term.wait(r"pace: 1x \(p\)")
        term.keys("s")
        term.wait(r"consent confirmed")
        term.keys("y")
        term.wait(r"running: P001", 240)  # loads the estimator first
        term.wait(r"x Stop")
        footer = _footer(term)
        for hint in ("s Start", "d Driver", "p Pace"):
            assert hint not in footer, footer
        term.keys("p")
        term.keys("x")  # p did nothing: x asks to stop the trial
        term.wait(r"Stop P001's running trial\?")
        assert "pace: 1x (p)" in term.screen()
        term.text("checking the keys")  # x asks why; the reason is audited
        term.keys("Enter")
        term.wait(r"status: interrupted")
        term.wait(r"s Start d Driver p Pace")
        _quit(term)
    finally:
        term.close()


@pytest.fixture
def notes_study(tmp_path: Path) -> Iterator[Path]:
    from db.migrate import open_database
    from study.protocol.design import parse_design
    from study.protocol.roster import add_participant, create_study
    from tests.study.tui.test_run_session import NOTES_DESIGN

    db = tmp_path / "notes.db"
    engine = open_database(str(db), create=True)
    create_study(engine, parse_design(NOTES_DESIGN), NOTES_DESIGN)
    add_participant(engine, "novice")
    engine.dispose()
    yield db


@pytest.mark.parametrize("task", ["lcca", "notes"])
def test_the_task_keys_are_whole_during_a_keyboard_trial(
    task: str, terminal: Path, notes_study: Path
) -> None:
    from study.protocol.tasks import get_task

    db = terminal if task == "lcca" else notes_study
    term = _start(db)
    try:
        _pick_first(term)
        term.keys("d")
        term.wait(r"driver: keyboard")
        term.keys("s")
        term.wait(r"consent confirmed")
        term.keys("y")
        term.wait(r"running: P001", 240)
        hints = live_view(get_task(task)).key_hints
        line = term.wait(rf"^ *{_literal(hints)} *$")
        assert line.group(0).strip() == hints
        term.keys("x")
        term.wait(r"Stop P001's running trial\?")
        term.text("checking the key hints")  # x asks why; the reason is audited
        term.keys("Enter")
        term.wait(r"status: interrupted")
        _quit(term)
    finally:
        term.close()


def _literal(text: str) -> str:
    import re

    return re.escape(text)


@pytest.mark.parametrize(
    "key",
    [
        "F1",
        "F2",
        "F3",
        "F5",
    ],
)
def test_every_tab_and_the_help_key_at_60x20(key: str, terminal: Path) -> None:
    term = _start(terminal, size=(60, 20))
    try:
        bar = term.screen().splitlines()[0]
        for label in ("F1 Home", "F2 People", "F3 Run", "F4 TLX", "F5 Stats", "F6 Calib"):
            assert label in bar, bar
        term.keys(key)
        term.wait(SHOWN[key])
        try:
            term.wait(r"\^q Quit \? Help", 10)
        except AssertionError:
            pytest.fail(f"{key} at 60 x 20: {_footer(term)!r}")
        _quit(term)
    finally:
        term.close()
