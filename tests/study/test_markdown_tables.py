"""A group name with Markdown and HTML in it (`a|b<i>`, which the design allows): every
table `study analyze` writes keeps its columns, and the name shows as typed, not as
markup."""

from __future__ import annotations

from pathlib import Path

from study.cli import main
from study.protocol.design import TEMPLATE
from tests.study.crossover_csv import crossover_trials

NAME = "a|b<i>"


def _cells(line: str) -> list[str]:
    """The cells of a pipe-table row, split on pipes not escaped with a backslash."""
    cells, cell, escaped = [], "", False
    for ch in line.strip()[1:-1]:
        if ch == "|" and not escaped:
            cells.append(cell.strip())
            cell = ""
        else:
            cell += ch
        escaped = ch == "\\" and not escaped
    return [*cells, cell.strip()]


def test_a_group_named_with_markup_keeps_every_tables_columns(tmp_path: Path) -> None:
    trials = crossover_trials(seed=5)
    trials["group"] = trials["group"].replace({"outsider": NAME})
    trials.to_csv(tmp_path / "t.csv", index=False)
    design = tmp_path / "d.toml"
    design.write_text(TEMPLATE.replace("outsider = 20", f'"{NAME}" = 20', 1))
    db = str(tmp_path / "s.db")
    assert main(["init", "--design", str(design), "--db", db]) == 0
    assert main(["import", "--trials", str(tmp_path / "t.csv"), "--enrol-new", "--db", db]) == 0
    out = tmp_path / "out"
    assert main(["analyze", "--out", str(out), "--db", db]) == 0
    pages = sorted(out.glob("*.md"))
    assert out / "descriptives.md" in pages
    seen = 0
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert "<i>" not in text, page.name  # no raw HTML reaches a renderer
        rows: list[list[str]] = []
        for line in [*text.splitlines(), ""]:
            if line.startswith("|"):
                rows.append(_cells(line))
                continue
            if rows:  # one table ended: every row as wide as its header
                assert {len(r) for r in rows} == {len(rows[0])}, (page.name, rows[0])
                seen += sum("a\\|b&lt;i>" in "".join(r) for r in rows)
                rows = []
    assert seen >= 3  # the group's rows, escaped, in the tables
