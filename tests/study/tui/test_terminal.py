"""The real `study tui` command in a pseudo-terminal: it starts, shows the overview, quits
cleanly; closing the terminal mid-trial keeps the trial as interrupted."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import pexpect
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from db.models.audit import AuditEntry
from db.models.trial import SampleChunk, Trial
from study.tui.trial_runner import STOPPED_REASON
from tests.study.conftest import modules_loaded


def test_study_tui_in_a_pseudo_terminal(study_engine: Engine, tmp_path: Path) -> None:
    db = study_engine.url.database
    study = Path(sys.executable).with_name("study")
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "80", "LINES": "24"}
    child = pexpect.spawn(
        str(study),
        ["tui", "--db", str(db)],
        dimensions=(24, 80),
        env=env,
        cwd=str(tmp_path),
        timeout=90,
        encoding="utf-8",
    )
    # the overview, filled from the database (DESIGN in conftest: 2 + 2 planned), and
    # the footer's bindings; in whatever order the terminal receives them (the footer
    # can be painted before or after the roster arrives from its worker)
    wanted = [
        "Study: tui test",
        r"Sessions done: 0 of 2 enrolled \(4 planned\)",
        "next trial: P001 lcca/VO trial 1",
        "Quit",
    ]
    try:
        seen: set[int] = set()
        while len(seen) < len(wanted):
            seen.add(child.expect(wanted))
        # quit at once, while the other screens are still being mounted: the app waits
        # for them and exits cleanly (it used to print Textual's NoMatches traceback)
        child.sendcontrol("q")
        child.expect(pexpect.EOF)
    finally:
        child.close(force=True)
    assert child.exitstatus == 0
    assert "Traceback" not in child.before
    assert "NoMatches" not in child.before


def test_the_overview_loads_neither_numpy_nor_the_other_screens(study_engine: Engine) -> None:
    # `study bench tui` times the start; this keeps what it measured: the `study tui`
    # command, the app and its roster query import no numerics and no later screen
    db = study_engine.url.database
    code = (
        "from study.cli import cli; cli.get_command(None, 'tui'); "
        "from db.migrate import open_database; from study.tui import StudyServices, make_app; "
        f"engine = open_database({db!r}, create=False); "
        "StudyServices(engine, lambda: None).roster(); engine.dispose()"
    )
    heavy = (
        "numpy",
        "pandas",
        "torch",
        "scipy",
        "alembic",
        "study.tui.run_pane",
        "study.tui.analysis_pane",
        "study.tui.tlx_pane",
        "study.commands.analyze",
    )
    assert modules_loaded(code, heavy) == []


def test_the_later_screens_load_no_statistics() -> None:
    # they are mounted before the run screen can prepare the simulation:
    # the analysis screen loads scipy.stats and statsmodels only when it analyses
    code = (
        "from study.tui.app import StudyApp; "
        "from study.tui.analysis_pane import AnalysisPane; "
        "from study.tui.calibration_pane import CalibrationPane; "
        "from study.tui.participants import ParticipantsPane; "
        "from study.tui.run_pane import RunPane; from study.tui.tlx_pane import TlxPane"
    )
    heavy = ("pandas", "scipy", "statsmodels", "pingouin", "matplotlib")
    assert modules_loaded(code, heavy) == []


def test_closing_the_terminal_mid_trial_marks_the_trial_interrupted(
    study_engine: Engine, tmp_path: Path
) -> None:
    # the terminal window closes (SIGHUP) while P001's trial runs: the app stops the
    # trial, which is kept as interrupted with its committed samples, and exits
    db = study_engine.url.database
    study = Path(sys.executable).with_name("study")
    env = {**os.environ, "TERM": "xterm-256color"}
    child = pexpect.spawn(
        str(study),
        ["tui", "--db", str(db), "--pace", "1"],
        dimensions=(24, 80),
        env=env,
        cwd=str(tmp_path),
        timeout=120,
        encoding="utf-8",
    )
    try:
        child.expect("Sessions done")
        child.send("\x1bOR")  # F3: the run screen
        child.expect("pick a participant")
        child.send("\r")  # F3 focused the participant list: open it, its options drawn
        child.expect("P002")
        child.send("\x1b[B")  # down to P001
        child.send("\r")  # choose it
        child.expect("next: P001")
        child.send("s")
        child.expect("consent")  # the session checklist
        child.send("y")
        child.expect("running: P001")
        child.expect(r"t +[1-9]\.\d s")  # a second of the trial has gone by
        child.kill(signal.SIGHUP)
        child.expect(pexpect.EOF)
        child.wait()
    finally:
        child.close(force=True)
    assert child.exitstatus == 128 + signal.SIGHUP
    with Session(study_engine) as session:
        trial = session.scalars(select(Trial)).one()
        samples = session.scalar(select(func.coalesce(func.sum(SampleChunk.n_samples), 0)))
        entry = session.scalars(select(AuditEntry).where(AuditEntry.field == "status")).one()
    assert trial.status == "interrupted"
    assert samples >= 100
    assert (entry.old_value, entry.new_value, entry.reason) == (
        "running",
        "interrupted",
        STOPPED_REASON,
    )
