"""The results tables a paper takes: one display frame per table, written as CSV (raw
numbers), Markdown and LaTeX (booktabs, pandas' Styler), each with a caption that names
its methods, the data source and the exclusions.

Every caption is built here from the same facts as `methods.md` (`study.analysis.methods`),
so a table never says less than the methods paragraph.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from study.analysis.apa import bounded_text, p_text
from study.analysis.methods import anova_method, comparison_method, lmm_method
from study.analysis.stats import Analysis


@dataclass(frozen=True)
class Table:
    """One results table: raw numbers for the CSV, formatted cells and a caption."""

    name: str
    raw: pd.DataFrame
    display: pd.DataFrame
    caption: str

    def markdown(self) -> str:
        header = "| " + " | ".join(self.display.columns) + " |"
        rule = "|" + "---|" * len(self.display.columns)
        body = ["| " + " | ".join(map(str, r)) + " |" for r in self.display.to_numpy()]
        if not body:
            body = ["| " + " | ".join(["-"] * len(self.display.columns)) + " |"]
        lines = [f"**Table: {self.name}.** {self.caption}", "", header, rule, *body]
        return "\n".join(lines) + "\n"

    def latex(self) -> str:
        styler = (
            self.display.style.hide(axis="index")
            .format(escape="latex")
            .format_index(escape="latex", axis=1)
        )
        text = styler.to_latex(
            hrules=True,
            caption=tex_escape(self.caption),
            label=f"tab:{self.name}",
            position_float="centering",
        )
        return text.replace("< .001", "$<$ .001")  # '<' is a text-mode glyph only in T1

    def write(self, folder: Path, data_source: str) -> list[Path]:
        """NAME.csv (raw numbers; a data_source column, for a table may travel alone),
        NAME.md and NAME.tex (formatted, captioned)."""
        from study.protocol.export_files import escape_frame  # spreadsheet-safe text

        paths = [folder / f"{self.name}.{ext}" for ext in ("csv", "md", "tex")]
        escape_frame(self.raw.assign(data_source=data_source)).to_csv(paths[0], index=False)
        paths[1].write_text(self.markdown())
        paths[2].write_text(self.latex())
        return paths


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


def _mean_sd(means: pd.Series, sds: pd.Series) -> list[str]:
    return [f"{_num(m)} ({_num(s)})" for m, s in zip(means, sds, strict=True)]


def _preamble(analysis: Analysis) -> str:
    return f"{analysis.source.note}. " if analysis.source.note else ""


TEST_LABELS = {"paired_t": "paired t", "wilcoxon": "Wilcoxon signed-rank"}
EFFECT_LABELS = {"hedges_g_av": "Hedges' g_av", "rank_biserial": "rank-biserial r"}
TERM_LABELS = {"Intercept": "intercept", "C(condition, Treatment('VO'))[T.HV]": "HV"}


def _statistic(test: str, value: float, n: int) -> str:
    """t with its df (n - 1 pairs); V, the Wilcoxon statistic as R reports it."""
    if test == "paired_t":
        return f"t({int(n) - 1}) = {_num(value, 2)}"
    return f"V = {_num(value, 1)}" if test == "wilcoxon" else _num(value)


def _effect(value: float, kind: str) -> str:
    label = EFFECT_LABELS.get(kind, kind)
    text = bounded_text(value) if kind == "rank_biserial" else _num(value, 2)
    return f"{label} = {text}"


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


def comparisons_table(analysis: Analysis) -> Table:
    c = analysis.comparisons
    display = pd.DataFrame(
        {
            "task": c["task"],
            "measure": c["measure"],
            "group": c["group"],
            "n": c["n"],
            "VO mean (SD)": _mean_sd(c["mean_vo"], c["sd_vo"]),
            "HV mean (SD)": _mean_sd(c["mean_hv"], c["sd_hv"]),
            "test": c["test"].map(TEST_LABELS),
            "statistic": [
                _statistic(t, v, n)
                for t, v, n in zip(c["test"], c["statistic"], c["n"], strict=True)
            ],
            "p": [p_text(v) for v in c["p"]],
            "p from": c["p_method"],
            "p (Holm)": [p_text(v) for v in c["p_holm"]],
            "effect size": [
                _effect(v, k) for v, k in zip(c["effect_size"], c["effect_size_kind"], strict=True)
            ],
        }
    )
    exclusions = "; ".join(analysis.exclusions) or "none"
    caption = f"{_preamble(analysis)}{comparison_method()} Exclusions: {exclusions}."
    return Table("comparisons", c, display, caption)


def anova_table(analysis: Analysis) -> Table:
    a = analysis.mixed_anova
    display = pd.DataFrame(
        {
            "task": a["task"],
            "measure": a["measure"],
            "source": a["source"],
            "F": [_num(v, 2) for v in a["F"]],
            "df": [f"{d1:g}, {d2:g}" for d1, d2 in zip(a["df1"], a["df2"], strict=True)],
            "p": [p_text(v) for v in a["p"]],
            "partial eta squared": [bounded_text(v, 3) for v in a["np2"]],
            "SS type": a["ss_type"].map(lambda t: "II" if t == 2 else "III"),
        }
    )
    return _model_table(
        analysis, "mixed_anova", a, display, anova_method(analysis.ss_type), "mixed ANOVA"
    )


def lmm_table(analysis: Analysis) -> Table:
    m = analysis.lmm
    display = pd.DataFrame(
        {
            "task": m["task"],
            "measure": m["measure"],
            "term": [term_label(t) for t in m["term"]],
            "estimate": [_num(v, 4) for v in m["estimate"]],
            "SE": [_num(v, 4) for v in m["se"]],
            "p (Wald z)": [p_text(v) for v in m["p"]],
        }
    )
    return _model_table(analysis, "lmm", m, display, lmm_method(), "mixed model")


def _model_table(
    analysis: Analysis,
    name: str,
    frame: pd.DataFrame,
    display: pd.DataFrame,
    method: str,
    model: str,
) -> Table:
    """A model's table, its caption noting the warnings the fit of `model` raised."""
    notes = "; ".join(analysis.warnings_about(model)) or "none"
    return Table(name, frame, display, f"{_preamble(analysis)}{method} Notes: {notes}.")


def descriptives_table(analysis: Analysis) -> Table:
    d = analysis.descriptives
    display = pd.DataFrame(
        {
            "task": d.get("task", []),
            "measure": d.get("measure", []),
            "group": d.get("group", []),
            "condition": d.get("condition", []),
            "n": d.get("n", []),
            "mean": [_num(v) for v in d.get("mean", [])],
            "SD": [_num(v) for v in d.get("sd", [])],
            "median": [_num(v) for v in d.get("median", [])],
            "IQR": [_num(v) for v in d.get("iqr", [])],
            "95 % CI": [
                f"[{_num(lo)}, {_num(hi)}]"
                for lo, hi in zip(d.get("ci_low", []), d.get("ci_high", []), strict=True)
            ],
        }
    )
    caption = (
        f"{_preamble(analysis)}Participant means (the mean of each block's measured trials; "
        "NASA-TLX as rated): n, mean, SD, median, interquartile range and the t-based 95 % "
        "confidence interval of the mean."
    )
    return Table("descriptives", d, display, caption)


def all_tables(analysis: Analysis) -> list[Table]:
    return [
        descriptives_table(analysis),
        comparisons_table(analysis),
        anova_table(analysis),
        lmm_table(analysis),
    ]
