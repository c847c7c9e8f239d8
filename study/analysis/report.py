"""The analysis written out: Markdown and LaTeX tables, a CSV of every test, and JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pandas as pd

from study.analysis.stats import Analysis

COMPARISON_KEYS = (
    "task", "measure", "group", "n", "mean_vo", "mean_hv", "sd_vo", "sd_hv", "test",
    "statistic", "p", "p_holm", "effect_size", "effect_size_kind",
)  # fmt: skip
ANOVA_KEYS = ("task", "measure", "source", "F", "df1", "df2", "p", "np2")
LMM_KEYS = ("task", "measure", "term", "estimate", "se", "p")


def _records(frame: pd.DataFrame, keys: tuple[str, ...]) -> list[dict[str, Any]]:
    if not len(frame):
        return []
    out = []
    for row in frame[list(keys)].to_dict("records"):
        out.append(
            {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()}
        )
    return out


def to_json(analysis: Analysis) -> dict[str, Any]:
    return {
        "comparisons": _records(analysis.comparisons, COMPARISON_KEYS),
        "mixed_anova": _records(analysis.mixed_anova, ANOVA_KEYS),
        "lmm": _records(analysis.lmm, LMM_KEYS),
        "descriptives": _records(
            analysis.descriptives,
            (
                "task",
                "measure",
                "group",
                "condition",
                "n",
                "mean",
                "sd",
                "median",
                "iqr",
                "ci_low",
                "ci_high",
            ),
        ),
        "exclusions": analysis.exclusions,
        "warnings": analysis.warnings,
    }


def _p(p: float) -> str:
    return "< .001" if p < 0.001 else f"{p:.3f}".lstrip("0")


def markdown(analysis: Analysis) -> str:
    lines = ["# VO vs HV within each group", ""]
    lines += [
        "| task | measure | group | n | VO mean (SD) | HV mean (SD) | test | statistic | p "
        "| p (Holm) | effect size |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in analysis.comparisons.to_dict("records"):
        lines.append(
            f"| {r['task']} | {r['measure']} | {r['group']} | {r['n']} | {r['mean_vo']:.3f} "
            f"({r['sd_vo']:.3f}) | {r['mean_hv']:.3f} ({r['sd_hv']:.3f}) | {r['test']} | "
            f"{r['statistic']:.3f} | {_p(r['p'])} | {_p(r['p_holm'])} | "
            f"{r['effect_size']:.2f} ({r['effect_size_kind']}) |"
        )
    lines += [
        "",
        "# Group x condition mixed ANOVA",
        "",
        "| task | measure | source | F | df | p | partial eta^2 |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in analysis.mixed_anova.to_dict("records"):
        lines.append(
            f"| {r['task']} | {r['measure']} | {r['source']} | {r['F']:.2f} | "
            f"{r['df1']:g}, {r['df2']:g} | {_p(r['p'])} | {r['np2']:.3f} |"
        )
    lines += [
        "",
        "# Linear mixed model (random intercept per participant)",
        "",
        "| task | measure | term | estimate | SE | p |",
        "|---|---|---|---|---|---|",
    ]
    for r in analysis.lmm.to_dict("records"):
        lines.append(
            f"| {r['task']} | {r['measure']} | {r['term']} | {r['estimate']:.4f} | "
            f"{r['se']:.4f} | {_p(r['p'])} |"
        )
    lines += ["", "# Exclusions", ""] + [f"- {e}" for e in analysis.exclusions or ["none"]]
    lines += ["", "# Warnings", ""] + [f"- {w}" for w in analysis.warnings or ["none"]]
    return "\n".join(lines) + "\n"


def latex(analysis: Analysis) -> str:
    c = analysis.comparisons
    if not len(c):
        return "% no comparisons\n"
    table = c[["measure", "group", "n", "mean_vo", "mean_hv", "test", "p", "p_holm", "effect_size"]]
    caption = "VO vs HV within each group (participant means). Exclusions: " + (
        "; ".join(analysis.exclusions) or "none"
    )
    return table.to_latex(index=False, float_format="%.3f", caption=caption.replace("_", r"\_"),
                          label="tab:vo-hv")  # fmt: skip


def write(analysis: Analysis, out_dir: Path, json_path: Path | None) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {
        "comparisons.md": markdown(analysis),
        "comparisons.tex": latex(analysis),
    }
    for name, text in paths.items():
        (out_dir / name).write_text(text)
    tests = pd.concat(
        [
            analysis.comparisons.assign(analysis="paired comparison"),
            analysis.mixed_anova.assign(analysis="mixed ANOVA"),
            analysis.lmm.assign(analysis="linear mixed model"),
            # the exclusions and notes travel with the tests
            pd.DataFrame({"analysis": "exclusion", "note": analysis.exclusions}),
            pd.DataFrame({"analysis": "note", "note": analysis.warnings}),
        ],
        ignore_index=True,
    )
    tests.to_csv(out_dir / "tests.csv", index=False)
    analysis.descriptives.to_csv(out_dir / "descriptives.csv", index=False)
    data = to_json(analysis)
    target = json_path or out_dir / "analysis.json"
    target.write_text(json.dumps(data, indent=2) + "\n")
    return [out_dir / n for n in paths] + [
        out_dir / "tests.csv",
        out_dir / "descriptives.csv",
        target,
    ]
