"""The real `study tui` command in a pseudo-terminal: it starts, shows the overview, quits."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pexpect
from sqlalchemy import Engine


def test_study_tui_in_a_pseudo_terminal(study_engine: Engine, tmp_path: Path) -> None:
    db = study_engine.url.database
    study = Path(sys.executable).with_name("study")
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "80", "LINES": "24"}
    child = pexpect.spawn(
        str(study), ["tui", "--db", str(db)], dimensions=(24, 80), env=env, cwd=str(tmp_path),
        timeout=90, encoding="utf-8",
    )  # fmt: skip
    try:
        # the overview, filled from the database (DESIGN in conftest: 2 + 2 planned)
        child.expect("Study: tui test")
        child.expect(r"Sessions done: 0 of 2 enrolled \(4 planned\)")
        child.expect("next trial: P001 lcca/VO trial 1")
        child.expect("Quit")  # the footer's bindings
        child.sendcontrol("q")
        child.expect(pexpect.EOF)
    finally:
        child.close(force=True)
    assert child.exitstatus == 0
