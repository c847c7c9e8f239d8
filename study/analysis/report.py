"""The analysis written out (`study analyze`, `study demo`).

In OUT/: `methods.md` (the methods paragraph with the software versions); the tables
`descriptives`, `comparisons`, `mixed_anova` and `lmm`, each as CSV (raw numbers),
Markdown and LaTeX (booktabs) with a caption naming its methods; `tests.csv` (every test,
exclusion and note in one file); and `analysis.json`. A study with several tasks also
gets OUT/<task>/ with that task's tables and methods, one set each.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pandas as pd

from study.analysis.methods import methods_json, methods_markdown
from study.analysis.stats import Analysis
from study.analysis.tables import all_tables

COMPARISON_KEYS = (
    "task",
    "measure",
    "group",
    "n",
    "mean_vo",
    "mean_hv",
    "sd_vo",
    "sd_hv",
    "test",
    "statistic",
    "p",
    "p_holm",
    "effect_size",
    "effect_size_kind",
    "p_method",
)
ANOVA_KEYS = ("task", "measure", "source", "F", "df1", "df2", "p", "np2", "ss_type")
LMM_KEYS = ("task", "measure", "term", "estimate", "se", "p", "p_method")
DESCRIPTIVE_KEYS = (
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
)


def _records(frame: pd.DataFrame, keys: tuple[str, ...]) -> list[dict[str, Any]]:
    if not len(frame):
        return []
    out = []
    for row in frame[list(keys)].to_dict("records"):
        # NaN, and the infinite F of a residual that is exactly zero: null (strict JSON)
        out.append(
            {
                k: None if isinstance(v, float) and not math.isfinite(v) else v
                for k, v in row.items()
            }
        )
    return out


def to_json(analysis: Analysis) -> dict[str, Any]:
    return {
        "data_source": analysis.source.to_dict(),
        "methods": methods_json(analysis),
        "comparisons": _records(analysis.comparisons, COMPARISON_KEYS),
        "mixed_anova": _records(analysis.mixed_anova, ANOVA_KEYS),
        "lmm": _records(analysis.lmm, LMM_KEYS),
        "descriptives": _records(analysis.descriptives, DESCRIPTIVE_KEYS),
        "exclusions": analysis.exclusions,
        "warnings": analysis.warnings,
    }


def _write_set(analysis: Analysis, folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / "methods.md"]
    paths[0].write_text(methods_markdown(analysis))
    for table in all_tables(analysis):
        paths += table.write(folder, analysis.source.label)
    return paths


def write(analysis: Analysis, out_dir: Path, json_path: Path | None) -> list[Path]:
    from study.protocol.export_files import escape_frame

    paths = _write_set(analysis, out_dir)
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
    ).assign(data_source=analysis.source.label)
    escape_frame(tests).to_csv(out_dir / "tests.csv", index=False)  # spreadsheet-safe text
    target = json_path or out_dir / "analysis.json"
    target.write_text(json.dumps(to_json(analysis), indent=2) + "\n")
    paths += [out_dir / "tests.csv", target]
    tasks = analysis.tasks
    if len(tasks) > 1:
        for task in tasks:
            paths += _write_set(analysis.for_task(task), out_dir / task)
    return paths
