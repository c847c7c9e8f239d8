"""MkDocs hooks: the benchmarks page drawn from `benchmarks/results/*.json`, the database
schema from `db.models` and the command-line reference from the `study` command
(`study.commands.reference`); and every citation key (`[endovascular]`) a link to its
entry in the bibliography.

`docs/benchmarks.md` holds a marker; at build time it is replaced by a table with one
row per `[[figure]]` of `benchmarks/index.toml`: the value read from its JSON file at
its key path, the target, whether the value meets it and the command that measures it.
A figure whose file or key is missing fails the build (`mkdocs build --strict` turns the
raised error into a failure), so the page can never show a number the results do not
hold; so does a target the build cannot judge, so no miss passes unflagged.

Whether a target is met is read from the target itself when it is a comparison
(`<= 0.5`, `>= 10 %`, `<= 30 s`, `< 2 ms`, `>= 19 of 21 on each seed`, `6 of 6`) or a
range (`0.90-0.98`). A target in words the build cannot read (`about 8 Hz`, `near 1`,
`practice named`) carries a `check` in the index: clauses joined by ` and `, each
`OP NUMBER` on the figure's value, `OP @KEY` against the value at another key of the
same file, or `KEY contains WORD` (a list at KEY holds WORD).
"""

from __future__ import annotations

import json
import posixpath
import re
import tomllib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
INDEX = ROOT / "benchmarks" / "index.toml"
RESULTS = ROOT / "benchmarks" / "results"
MARKER = "<!-- benchmarks-table -->"
SCHEMA_MARKER = "<!-- database-schema -->"
CLI_MARKER = "<!-- cli-reference -->"
BIBLIOGRAPHY = ROOT / "docs" / "bibliography.md"


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


_NUMBER = r"[-+]?\d+(?:\.\d+)?"
_COMPARISON = re.compile(
    rf"^(?P<op><=|>=|<|>|==)?\s*(?P<number>{_NUMBER})\s*(?P<unit>%|x|[A-Za-z]+)?"
    rf"(?:\s+of\s+\d+(?:\s+on each \w+)?)?$"
)
_RANGE = re.compile(rf"^(?P<low>{_NUMBER})\s*(?:-|to)\s*(?P<high>{_NUMBER})$")
_CLAUSE = re.compile(r"^(?:(?P<key>[\w.]+)\s+)?(?P<op><=|>=|<|>|==|contains)\s*(?P<rhs>\S+)$")
_OPS = {
    "<=": lambda a, b: a <= b,
    ">=": lambda a, b: a >= b,
    "<": lambda a, b: a < b,
    ">": lambda a, b: a > b,
    "==": lambda a, b: a == b,
}


def number(value: Any) -> float:
    """A figure's value as a number: a number itself, or a string's leading number
    (`'20 of 21'` is 20, `'1.86 (8 of 27 beyond 1.96 SE)'` is 1.86)."""
    if isinstance(value, bool):
        raise ValueError(f"{value!r} is not a number")
    if isinstance(value, int | float):
        return float(value)
    match = re.match(_NUMBER, str(value).strip())
    if not match:
        raise ValueError(f"{value!r} does not start with a number")
    return float(match.group())


def judge(figure: dict[str, Any], data: Any, value: Any) -> str:
    """Whether a figure's value meets its target: `yes`, `no`, or `no target`.

    A percent target (`>= 10 %`) against a value shown as a percent (a `format` ending
    in `%`, the value a fraction) is read as the fraction. A target neither a
    comparison nor a range, without a `check`, raises ValueError."""
    target = figure.get("target", "").strip()
    check = figure.get("check", "").strip()
    if not target and not check:
        return "no target"
    if check:
        met = all(_clause(clause.strip(), figure, data, value) for clause in check.split(" and "))
        return "yes" if met else "no"
    shown_as_percent = figure.get("format", "").endswith("%")
    scale = 100.0 if shown_as_percent else 1.0
    span = _RANGE.match(target)
    if span:
        low, high = float(span["low"]) / scale, float(span["high"]) / scale
        return "yes" if low <= number(value) <= high else "no"
    match = _COMPARISON.match(target)
    if not match:
        raise ValueError(
            f"benchmarks/index.toml: target {target!r} of {figure['what']!r} is neither a "
            "comparison (<= 0.5) nor a range (0.90-0.98); give the figure a check"
        )
    unit = match["unit"]
    figure_unit = figure.get("unit", "").split(" ")[0]
    if unit and unit not in ("%", "x") and unit != figure_unit:
        raise ValueError(
            f"benchmarks/index.toml: target {target!r} of {figure['what']!r} is in {unit}, "
            f"the value in {figure_unit or 'no unit'}"
        )
    bound = float(match["number"]) / (scale if unit == "%" else 1.0)
    return "yes" if _OPS[match["op"] or "=="](number(value), bound) else "no"


def _clause(clause: str, figure: dict[str, Any], data: Any, value: Any) -> bool:
    """One clause of a figure's check (see the module's docstring)."""
    match = _CLAUSE.match(clause)
    if not match:
        raise ValueError(
            f"benchmarks/index.toml: check {clause!r} of {figure['what']!r} is not "
            "OP NUMBER, OP @KEY or KEY contains WORD"
        )
    left = lookup(data, match["key"]) if match["key"] else value
    rhs = match["rhs"]
    if match["op"] == "contains":
        return isinstance(left, list) and rhs in left
    right = number(lookup(data, rhs[1:])) if rhs.startswith("@") else float(rhs)
    return bool(_OPS[match["op"]](number(left), right))


def figure_rows(index: Path = INDEX, results: Path = RESULTS) -> list[dict[str, str]]:
    """One row per figure of the index: area, what, value with unit, target, whether it
    is met, command."""
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
                "met": judge(figure, cache[name], value),
                "command": figure["command"],
            }
        )
    return rows


def table(rows: list[dict[str, str]]) -> str:
    """The Markdown tables of the rows: first a line counting the targets met and naming
    the misses, then one table per area (each area once, in the order the index first
    names it; its rows in the index's order)."""
    judged = [row for row in rows if row["met"] != "no target"]
    missed = [row for row in judged if row["met"] == "no"]
    met = len(judged) - len(missed)
    lines = [f"{met} of {len(judged)} targets met."]
    if missed:
        lines[0] += " Missed:"
        lines += [""] + [
            f"- {row['area']}: {row['what']} ({row['value']}, target {row['target']})"
            for row in missed
        ]
    areas: dict[str, list[dict[str, str]]] = {}
    for row in rows:
        areas.setdefault(row["area"], []).append(row)
    for area, members in areas.items():
        header = ["| measure | value | target | met | command |", "|---|---|---|---|---|"]
        lines += ["", f"### {area}", "", *header]
        for row in members:
            cells = [row["what"], row["value"], row["target"], row["met"], f"`{row['command']}`"]
            lines.append("| " + " | ".join(cells) + " |")
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


def citation_keys(bibliography: Path = BIBLIOGRAPHY) -> list[str]:
    """The keys the bibliography's entries start with (`- **[key]** ...`)."""
    text = bibliography.read_text(encoding="utf-8")
    return re.findall(r"^- \*\*\[([\w-]+)\]\*\*", text, re.MULTILINE)


# The parts of a page's HTML a citation is never linked in: code, an existing link, a
# tag itself (its attributes).
_UNLINKED = re.compile(r"<pre\b.*?</pre>|<code\b.*?</code>|<a\b.*?</a>|<[^>]*>", re.DOTALL)


def link_citations(html: str, keys: list[str], bibliography_url: str) -> str:
    """Each `[key]` of the text (not in code, not already a link) a link to the key's
    entry at `bibliography_url#key`."""
    if not keys:
        return html
    cited = re.compile(r"\[(" + "|".join(map(re.escape, keys)) + r")\]")

    def link(text: str) -> str:
        return cited.sub(lambda m: f'<a href="{bibliography_url}#{m[1]}">[{m[1]}]</a>', text)

    out, last = [], 0
    for match in _UNLINKED.finditer(html):
        out += [link(html[last : match.start()]), match.group()]
        last = match.end()
    out.append(link(html[last:]))
    return "".join(out)


def anchor_entries(html: str, keys: list[str]) -> str:
    """The bibliography's entries given the ids the citations link to."""
    for key in keys:
        html = html.replace(f"<strong>[{key}]</strong>", f'<strong id="{key}">[{key}]</strong>', 1)
    return html


def on_page_content(html: str, page: Any, files: Any, **_: Any) -> str:
    """Link the citation keys of every page to the bibliography's entries."""
    keys = citation_keys()
    if page.file.src_uri == "bibliography.md":
        return anchor_entries(html, keys)
    bibliography = files.get_file_from_path("bibliography.md")
    if bibliography is None:
        return html
    return link_citations(html, keys, relative_url(bibliography.url, page.file.url))


def relative_url(target: str, page: str) -> str:
    """The link from a page's URL to a target's (`explanation/models/` to `bibliography/`
    is `../../bibliography/`); a URL ending in `/` is a folder, else a file in one."""
    here = page.rstrip("/") if page.endswith("/") else posixpath.dirname(page)
    url = posixpath.relpath(target.rstrip("/") or ".", here or ".")
    return url + "/" if target.endswith("/") and not url.endswith("/") else url
