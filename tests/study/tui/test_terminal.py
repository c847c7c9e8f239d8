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
        child.sendcontrol("q")
        child.expect(pexpect.EOF)
    finally:
        child.close(force=True)
    assert child.exitstatus == 0
