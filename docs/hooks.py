"""MkDocs hooks: the benchmarks page drawn from `benchmarks/results/*.json`, the database
schema from `db.models` and the command-line reference from the `study` command
(`study.commands.reference`).

`docs/benchmarks.md` holds a marker; at build time it is replaced by a table with one
row per `[[figure]]` of `benchmarks/index.toml`: the value read from its JSON file at
its key path, the target and the command that measures it. A figure whose file or key
is missing fails the build (`mkdocs build --strict` turns the raised error into a
failure), so the page can never show a number the results do not hold.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
INDEX = ROOT / "benchmarks" / "index.toml"
RESULTS = ROOT / "benchmarks" / "results"
MARKER = "<!-- benchmarks-table -->"
SCHEMA_MARKER = "<!-- database-schema -->"
CLI_MARKER = "<!-- cli-reference -->"


def lookup(data: Any, key: str) -> Any:
    """The value at a dotted key path (`a.b.0.c`; digits index lists)."""
    value = data
    for part in key.split("."):
        if isinstance(value, list):
            value = value[int(part)]
        elif isinstance(value, dict) and part in value:
            value = value[part]
        else:
            raise KeyError(key)
    return value


def figure_rows(index: Path = INDEX, results: Path = RESULTS) -> list[dict[str, str]]:
    """One row per figure of the index: area, what, value with unit, target, command."""
    figures = tomllib.loads(index.read_text(encoding="utf-8"))["figure"]
    cache: dict[str, Any] = {}
    rows = []
    for figure in figures:
        name = figure["file"]
        if name not in cache:
            path = results / name
            if not path.is_file():
                raise FileNotFoundError(f"benchmarks/index.toml names {name}, not in {results}")
            cache[name] = json.loads(path.read_text(encoding="utf-8"))
        try:
            value = lookup(cache[name], figure["key"])
        except (KeyError, IndexError, ValueError) as exc:
            raise KeyError(f"benchmarks/index.toml: {name} has no {figure['key']!r}") from exc
        shown = format(value, figure["format"]) if "format" in figure else str(value)
        unit = figure.get("unit", "")
        rows.append(
            {
                "area": figure["area"],
                "what": figure["what"],
                "value": f"{shown} {unit}".strip(),
                "target": figure.get("target", ""),
                "command": figure["command"],
            }
        )
    return rows


def table(rows: list[dict[str, str]]) -> str:
    """The Markdown table of the rows, grouped by area in the index's order."""
    lines = []
    area = None
    for row in rows:
        if row["area"] != area:
            area = row["area"]
            header = ["| measure | value | target | command |", "|---|---|---|---|"]
            lines += ["", f"### {area}", "", *header]
        lines.append(f"| {row['what']} | {row['value']} | {row['target']} | `{row['command']}` |")
    return "\n".join(lines) + "\n"


def schema_tables() -> str:
    """Every table of the study database as `db.models` declares it (what the migrations
    must produce): each column with its type, whether it may be NULL, and its key."""
    import db.models  # noqa: F401  (registers every table on the metadata)
    from db.base import Base

    lines = []
    for name, tbl in sorted(Base.metadata.tables.items()):
        lines += ["", f"### `{name}`", "", "| column | type | NULL | key |", "|---|---|---|---|"]
        for column in tbl.columns:
            keys = []
            if column.primary_key:
                keys.append("primary")
            keys += [f"-> `{fk.target_fullname}`" for fk in column.foreign_keys]
            null = "yes" if column.nullable else "no"
            lines.append(f"| `{column.name}` | {column.type} | {null} | {' '.join(keys)} |")
    return "\n".join(lines) + "\n"


def on_page_markdown(markdown: str, page: Any, **_: Any) -> str:
    """Replace the markers of the benchmarks, database and command-line pages with what
    they stand for."""
    if MARKER in markdown:
        markdown = markdown.replace(MARKER, table(figure_rows()))
    if SCHEMA_MARKER in markdown:
        markdown = markdown.replace(SCHEMA_MARKER, schema_tables())
    if CLI_MARKER in markdown:
        from study.cli import cli
        from study.commands.reference import cli_reference

        markdown = markdown.replace(CLI_MARKER, cli_reference(cli))
    return markdown
