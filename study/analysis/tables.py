"""The results tables a paper takes: one table of formatted cells per table, written as
CSV (raw numbers), Markdown and LaTeX (booktabs, in the layout of pandas' Styler), each
with a caption that names its methods, the data source and the exclusions.

Every caption is built here from the same facts as `methods.md` (`study.analysis.methods`),
so a table never says less than the methods paragraph.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from study.analysis.apa import bounded_text, markdown_escape, p_text
from study.analysis.crossover_text import design_checks_cells, design_checks_method
from study.analysis.methods import (
    anova_method,
    comparison_method,
    evidence_method,
    lmm_method,
    success_method,
)
from study.analysis.mixed_model import LMM_COLUMNS
from study.analysis.stats import (
    ANOVA_COLUMNS,
    COMPARISON_COLUMNS,
    DESCRIPTIVE_COLUMNS,
    Analysis,
    Row,
)
from study.analysis.success import SUCCESS_COLUMNS
from study.protocol.cells import escape_cell

if TYPE_CHECKING:  # `Table.display` as a frame, for callers that want one
    import pandas as pd


@dataclass(frozen=True)
class Table:
    """One results table: raw numbers for the CSV, formatted cells and a caption."""

    name: str
    columns: tuple[str, ...]
    rows: list[Row]
    """The raw numbers, one dict per row."""
    header: tuple[str, ...]
    cells: list[list[Any]]
    """The formatted cells, one list per row in the order of `header`."""
    caption: str
    footer: str = ""
    """Printed under the table (the exclusions)."""

    @property
    def display(self) -> pd.DataFrame:
        """The formatted cells as a pandas frame."""
        # lazy: pandas costs 0.4 s at start-up
        import pandas as pd

        return pd.DataFrame(self.cells, columns=list(self.header))

    def markdown(self) -> str:
        """A pipe table, every cell escaped (`markdown_escape`: a group named `a|b<i>`
        neither splits a column nor passes raw HTML)."""
        header = "| " + " | ".join(map(markdown_escape, self.header)) + " |"
        rule = "|" + "---|" * len(self.header)
        body = ["| " + " | ".join(map(markdown_escape, r)) + " |" for r in self.cells]
        if not body:
            body = ["| " + " | ".join(["-"] * len(self.header)) + " |"]
        caption = markdown_escape(self.caption)
        lines = [f"**Table: {markdown_escape(self.name)}.** {caption}", "", header, rule, *body]
        if self.footer:
            lines += ["", markdown_escape(self.footer)]
        return "\n".join(lines) + "\n"

    def latex(self) -> str:
        """A booktabs table as pandas' `Styler.to_latex(hrules=True)` writes it: numeric
        columns right-aligned, text escaped (`latex_escape`), the caption and label."""
        numeric = [
            bool(self.cells) and all(_is_number(r[i]) for r in self.cells)
            for i in range(len(self.header))
        ]
        align = "".join("r" if n else "l" for n in numeric)
        lines = [
            "\\begin{table}",
            "\\centering",
            f"\\caption{{{tex_escape(self.caption)}}}",
            f"\\label{{tab:{self.name}}}",
            f"\\begin{{tabular}}{{{align}}}",
            "\\toprule",
            " & ".join(latex_escape(h) for h in self.header) + " \\\\",
            "\\midrule",
            *(" & ".join(_latex_cell(v) for v in r) + " \\\\" for r in self.cells),
            "\\bottomrule",
            "\\end{tabular}",
            *(
                [f"\\par\\smallskip{{\\footnotesize {tex_escape(self.footer)}}}"]
                if self.footer
                else []
            ),
            "\\end{table}",
        ]
        text = "\n".join(lines) + "\n"
        return text.replace("< .001", "$<$ .001")  # '<' is a text-mode glyph only in T1

    def write(self, folder: Path, data_source: str) -> list[Path]:
        """NAME.csv (raw numbers; a data_source column, for a table may travel alone),
        NAME.md and NAME.tex (formatted, captioned)."""
        paths = [folder / f"{self.name}.{ext}" for ext in ("csv", "md", "tex")]
        columns, rows = flat_columns(self.columns, self.rows)
        rows = [{**r, "data_source": data_source} for r in rows]
        write_csv(paths[0], [*columns, "data_source"], rows)
        paths[1].write_text(self.markdown())
        paths[2].write_text(self.latex())
        return paths


def flat_columns(columns: Sequence[str], rows: list[Row]) -> tuple[list[str], list[Row]]:
    """`rows` with one scalar per cell, as a CSV (and R's `read.csv`) wants them: an
    interval `[low, high]` under `NAME_low` and `NAME_high`, a record (the condition
    effect before and after) under `NAME_KEY` for each of its keys, recursively."""

    def flat(name: str, value: Any) -> dict[str, Any]:
        if isinstance(value, dict):
            return {k: v for key, x in value.items() for k, v in flat(f"{name}_{key}", x).items()}
        if isinstance(value, list | tuple) and len(value) == 2:
            return {f"{name}_low": value[0], f"{name}_high": value[1]}
        return {name: value}

    out = [{k: v for c in columns for k, v in flat(c, r.get(c)).items()} for r in rows]
    names = list(dict.fromkeys(k for r in out for k in r)) if out else list(columns)
    return names, out


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _latex_cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6f}"  # Styler's default precision
    return latex_escape(value) if isinstance(value, str) else str(value)


def latex_escape(text: str) -> str:
    """Text for a LaTeX cell, as pandas' Styler escapes it (`format(escape="latex")`)."""
    return (
        text.replace("\\", "ab2\u00a7=\u00a78yz")
        .replace("ab2\u00a7=\u00a78yz ", "ab2\u00a7=\u00a78yz\\space ")
        .replace("&", "\\&")
        .replace("%", "\\%")
        .replace("$", "\\$")
        .replace("#", "\\#")
        .replace("_", "\\_")
        .replace("{", "\\{")
        .replace("}", "\\}")
        .replace("~ ", "~\\space ")
        .replace("~", "\\textasciitilde ")
        .replace("^ ", "^\\space ")
        .replace("^", "\\textasciicircum ")
        .replace("ab2\u00a7=\u00a78yz", "\\textbackslash ")
    )


def _csv_formatters(columns: Sequence[str], rows: list[Row]) -> list[Any]:
    """Per column, how pandas' `to_csv` prints its cells: an integer column with a gap is
    a float column (20 -> 20.0), NaN and None are empty, floats their shortest repr."""
    out = []
    for c in columns:
        values = [r.get(c) for r in rows]
        ints = [v for v in values if isinstance(v, int) and not isinstance(v, bool)]
        present = [v for v in values if v is not None]
        as_float = bool(ints) and len(ints) < len(values) and len(ints) == len(present)
        out.append(as_float)
    return out


def _csv_cell(value: Any, as_float: bool) -> Any:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int):
        return repr(float(value)) if as_float else str(value)
    if isinstance(value, float):
        return repr(float(value))
    return escape_cell(value)  # spreadsheet-safe text


def write_csv(path: Path, columns: Sequence[str], rows: list[Row]) -> None:
    """`rows` as CSV with `columns`, cell by cell as pandas' `to_csv(index=False)` writes
    them (a missing key is an empty cell), text made spreadsheet-safe."""
    floats = _csv_formatters(columns, rows)
    with path.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(columns)
        for r in rows:
            writer.writerow(
                [_csv_cell(r.get(c), fl) for c, fl in zip(columns, floats, strict=True)]
            )


TEX_SPECIAL = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
}


def tex_escape(text: str) -> str:
    return "".join(TEX_SPECIAL.get(c, c) for c in text)


def _num(x: float | None, digits: int = 3) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"


def _preamble(analysis: Analysis) -> str:
    return f"{analysis.source.note}. " if analysis.source.note else ""


TEST_LABELS = {"paired_t": "paired t", "wilcoxon": "Wilcoxon signed-rank", "none": "none"}
EFFECT_LABELS = {"hedges_g_av": "Hedges' g_av", "rank_biserial": "rank-biserial r"}
TERM_LABELS = {"Intercept": "intercept", "C(condition, Treatment('VO'))[T.HV]": "HV"}


def _statistic(row: Row) -> str:
    """t with its df (n - 1 pairs); V, the signed-rank statistic; or why there is none."""
    test, value, n = row["test"], row["statistic"], row["n"]
    if test == "none":
        return f"not testable: {row['not_testable']}"
    if test == "paired_t":
        return f"t({int(n) - 1}) = {_num(value, 2)}"
    return f"V = {_num(value, 1)}" if test == "wilcoxon" else _num(value)


def _effect(value: float, kind: str) -> str:
    if not isinstance(kind, str):
        return "n/a"
    label = EFFECT_LABELS.get(kind, kind)
    text = bounded_text(value) if kind == "rank_biserial" else _num(value, 2)
    return f"{label} = {text}"


def _interval(x: float, low: float, high: float, digits: int) -> str:
    if not math.isfinite(x):
        return "n/a"
    return f"{_num(x, digits)} [{_num(low, digits)}, {_num(high, digits)}]"


def term_label(term: str) -> str:
    """A mixed-model term as a reader names it: 'HV', 'novice', 'HV x novice'."""
    parts = []
    for part in term.split(":"):
        if part in TERM_LABELS:
            parts.append(TERM_LABELS[part])
        elif "[T." in part:
            parts.append(part.split("[T.", 1)[1].rstrip("]"))
        else:
            parts.append(part)
    return " x ".join(parts)


def _exclusions_footer(analysis: Analysis) -> str:
    return "Exclusions: " + ("; ".join(analysis.exclusions) or "none") + "."


def comparisons_table(analysis: Analysis) -> Table:
    c = analysis.comparison_rows
    header = (
        "task",
        "measure",
        "group",
        "n",
        "VO mean (SD)",
        "HV mean (SD)",
        "test",
        "statistic",
        "p",
        "p from",
        "p (Holm)",
        "effect size",
        "M diff [95 % CI]",
        "d_z [95 % CI]",
        "BF10",
        "TOST p",
    )
    cells = [
        [
            r["task"],
            r["measure"],
            r["group"],
            r["n"],
            f"{_num(r['mean_vo'])} ({_num(r['sd_vo'])})",
            f"{_num(r['mean_hv'])} ({_num(r['sd_hv'])})",
            TEST_LABELS.get(r["test"], "nan"),
            _statistic(r),
            p_text(r["p"]),
            r["p_method"] if isinstance(r["p_method"], str) else "n/a",
            p_text(r["p_holm"]),
            _effect(r["effect_size"], r["effect_size_kind"]),
            _interval(r["mean_diff"], r["diff_ci_low"], r["diff_ci_high"], 3),
            _interval(r["dz"], r["dz_ci_low"], r["dz_ci_high"], 2),
            _num(r["bf10"], 2),
            p_text(r["tost_p"]),
        ]
        for r in c
    ]
    caption = (
        f"{_preamble(analysis)}{comparison_method()} {evidence_method(analysis.bounds.describe())}"
    )
    return Table(
        "comparisons", COMPARISON_COLUMNS, c, header, cells, caption, _exclusions_footer(analysis)
    )


def success_table(analysis: Analysis) -> Table:
    s = analysis.success_rows
    header = (
        "task",
        "group",
        "n",
        "VO success",
        "HV success",
        "VO only",
        "HV only",
        "p",
        "p (Holm)",
    )
    cells = [
        [
            r["task"],
            r["group"],
            r["n"],
            r["success_vo"],
            r["success_hv"],
            r["vo_only"],
            r["hv_only"],
            p_text(r["p"]),
            p_text(r["p_holm"]),
        ]
        for r in s
    ]
    caption = f"{_preamble(analysis)}{success_method()}"
    return Table(
        "success", SUCCESS_COLUMNS, s, header, cells, caption, _exclusions_footer(analysis)
    )


def anova_table(analysis: Analysis) -> Table:
    a = analysis.anova_rows
    header = ("task", "measure", "source", "F", "df", "p", "partial eta squared", "SS type")
    cells = [
        [
            r["task"],
            r["measure"],
            r["source"],
            _num(r["F"], 2),
            f"{r['df1']:g}, {r['df2']:g}",
            p_text(r["p"]),
            bounded_text(r["np2"], 3),
            "II" if r["ss_type"] == 2 else "III",
        ]
        for r in a
    ]
    return _model_table(
        analysis,
        "mixed_anova",
        (ANOVA_COLUMNS, a, header, cells),
        anova_method(analysis.ss_type),
        "mixed ANOVA",
    )


def lmm_label(row: Row) -> str:
    """A mixed-model row as a reader names it: the coefficient with its reference level
    ('HV (in expert)'), or the marginal mean or contrast over the groups."""
    if row.get("kind") == "marginal mean":
        return f"{row['term'].removeprefix('mean ')} (mean over groups)"
    if row.get("kind") == "marginal contrast":
        return f"{row['term']} (mean over groups)"
    label = term_label(row["term"])
    reference = row.get("reference") or ""
    group = reference.rsplit("group ", 1)[-1] if "group " in reference else ""
    is_condition = "[T." in row["term"] and row["term"].startswith("C(condition")
    if is_condition and ":" not in row["term"] and group:
        return f"{label} (in {group})"
    return label


def lmm_table(analysis: Analysis) -> Table:
    m = analysis.lmm_rows
    ddf = analysis.ddf
    header = ("task", "measure", "term", "estimate", "SE", "df", "95 % CI", f"p ({ddf})")
    cells = [
        [
            r["task"],
            r["measure"],
            lmm_label(r),
            _num(r["estimate"], 4),
            _num(r["se"], 4),
            _num(r.get("df"), 1),
            f"[{_num(r.get('ci_low'), 4)}, {_num(r.get('ci_high'), 4)}]",
            p_text(r["p"]) if r["p"] is not None else "",
        ]
        for r in m
    ]
    return _model_table(
        analysis,
        "lmm",
        (LMM_COLUMNS, m, header, cells),
        lmm_method(ddf, _references(m)),
        "mixed model",
    )


def _references(rows: list[Row]) -> list[str]:
    return list(dict.fromkeys(r["reference"] for r in rows if r.get("kind") == "coefficient"))


def _model_table(
    analysis: Analysis,
    name: str,
    parts: tuple[tuple[str, ...], list[Row], tuple[str, ...], list[list[Any]]],
    method: str,
    model: str,
) -> Table:
    """A model's table, its caption noting the warnings the fit of `model` raised."""
    notes = "; ".join(analysis.warnings_about(model)) or "none"
    caption = f"{_preamble(analysis)}{method} Notes: {notes}."
    return Table(name, *parts, caption, _exclusions_footer(analysis))


def descriptives_table(analysis: Analysis) -> Table:
    d = analysis.descriptive_rows
    header = (
        "task",
        "measure",
        "group",
        "condition",
        "n",
        "mean",
        "SD",
        "median",
        "IQR",
        "95 % CI",
    )
    cells = [
        [
            r["task"],
            r["measure"],
            r["group"],
            r["condition"],
            r["n"],
            _num(r["mean"]),
            _num(r["sd"]),
            _num(r["median"]),
            _num(r["iqr"]),
            f"[{_num(r['ci_low'])}, {_num(r['ci_high'])}]",
        ]
        for r in d
    ]
    caption = (
        f"{_preamble(analysis)}Participant means (the mean of each block's measured trials; "
        "NASA-TLX as rated): n, mean, SD, median, interquartile range and the t-based 95 % "
        "confidence interval of the mean."
    )
    return Table(
        "descriptives", DESCRIPTIVE_COLUMNS, d, header, cells, caption, _exclusions_footer(analysis)
    )


def all_tables(analysis: Analysis) -> list[Table]:
    return [
        descriptives_table(analysis),
        comparisons_table(analysis),
        anova_table(analysis),
        lmm_table(analysis),
        design_checks_table(analysis),
        success_table(analysis),
    ]


def design_checks_table(analysis: Analysis) -> Table:
    """The crossover's checks (`crossover`): one row per task, measure and effect."""
    # lazy: study.analysis.crossover costs 4 ms at start-up
    from study.analysis.crossover import CHECK_COLUMNS

    header, cells = design_checks_cells(analysis.design_checks)
    caption = f"{_preamble(analysis)}{design_checks_method()}"
    return Table("design_checks", CHECK_COLUMNS, analysis.design_checks, header, cells, caption)
