"""Habits the code keeps: no lab notebook in code or help text (issue numbers, dates,
an unnamed paper), no function ranked D or worse by radon, the type checker clean."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("study", "teleop_core", "db", "examples")
SUFFIXES = {".py", ".md", ".toml", ".mako", ".txt", ".cfg"}
CHECKED = (*PACKAGES, "tests")
"""The trees checked for every suffix; `benchmarks/` is checked for its Python only, since
its results and HISTORY.md rightly hold dates."""

NOTEBOOK = re.compile(
    r"\bissues?\s*#?\d+"  # "issue 24", "issue #24", "Issue 17's"
    r"|(?<![\w\"'&/])#\d{1,5}\b"  # "#24" (not a colour "#999999", not a URL fragment)
    r"|\bseed\s+00\d\b"  # a paper is cited by its bibliography key ("seed 000", "seed 001")
    r"|\b20\d\d-[01]\d-[0-3]\d\b",  # a date
    re.IGNORECASE,
)
"""What a docstring, comment or help text must not hold: results and their dates live in
`benchmarks/`, the papers are cited by their key in `docs/bibliography.md`."""


def notebook_lines(text: str) -> list[tuple[int, str]]:
    """The (line number, line) pairs of `text` that `NOTEBOOK` matches."""
    return [(n, line) for n, line in enumerate(text.splitlines(), 1) if NOTEBOOK.search(line)]


@pytest.mark.parametrize(
    ("line", "found"),
    [
        ("Sane sizes (issue 18: 2**63 trials were accepted)", True),
        ("the target band of Issue 24's fit", True),
        ("fixed in #41", True),
        ("the paper's gain (seed 000)", True),
        ("the surgeons' benchmark of Seed 001", True),
        ("simulated with --seed 1", False),
        ("Create Date: 2026-11-27", True),
        ('color="#999999", lw=0.6', False),
        ("the paper's gain ([endovascular], IV-D)", False),
        ("the tissue's push on the tip", False),
        ("20 engineering outsiders, 8 novice doctors", False),
    ],
)
def test_the_notebook_pattern_finds_what_it_should(line: str, found: bool) -> None:
    assert bool(notebook_lines(line)) is found


def checked_files() -> list[Path]:
    """Code, tests and benchmark scripts; not this file, whose examples are the pattern's
    test data."""
    files = [
        path
        for tree in CHECKED
        for path in sorted((ROOT / tree).rglob("*"))
        if path.suffix in SUFFIXES and "__pycache__" not in path.parts
    ]
    files += sorted((ROOT / "benchmarks").rglob("*.py"))
    return [path for path in files if path != Path(__file__).resolve()]


def test_code_and_help_hold_no_issue_numbers_dates_or_unnamed_papers() -> None:
    hits = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
        for path in checked_files()
        for n, line in notebook_lines(path.read_text(encoding="utf-8"))
    ]
    assert hits == [], "lab-notebook text in code:\n" + "\n".join(hits)


def test_no_function_is_ranked_d_or_worse_by_radon() -> None:
    """Cyclomatic complexity at most 20 (radon's rank C) everywhere: the command .ci/run
    runs, with radon's own ranking."""
    done = subprocess.run(
        [sys.executable, "-m", "radon", "cc", "-n", "D", *PACKAGES],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    assert done.stdout.strip() == "", "split these into steps:\n" + done.stdout
