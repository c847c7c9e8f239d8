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

from study.analysis.crossover import CHECK_COLUMNS, FIT_COLUMNS
from study.analysis.methods import methods_json, methods_markdown
from study.analysis.mixed_model import LMM_COLUMNS
from study.analysis.stats import (
    ANOVA_COLUMNS,
    COMPARISON_COLUMNS,
    DESCRIPTIVE_COLUMNS,
    Analysis,
    Row,
)
from study.analysis.success import SUCCESS_COLUMNS
from study.analysis.tables import all_tables, write_csv

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
    # added beside the keys above: the interval, d_z, TOST, BF10 and the edges
    "df",
    "mean_diff",
    "diff_ci_low",
    "diff_ci_high",
    "dz",
    "dz_ci_low",
    "dz_ci_high",
    "g_av",
    "tost_bound",
    "tost_p",
    "bf10",
    "constant_diff",
    "not_testable",
    "holm_family",
)
# the JSON's keys of the other three tables are their columns, in their order
ANOVA_KEYS, LMM_KEYS, DESCRIPTIVE_KEYS = ANOVA_COLUMNS, LMM_COLUMNS, DESCRIPTIVE_COLUMNS


def _strict(v: Any) -> Any:
    """NaN and infinities as null (strict JSON), inside lists and dicts too."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _strict(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_strict(x) for x in v]
    return v


def _records(rows: list[Row], keys: tuple[str, ...]) -> list[dict[str, Any]]:
    # NaN (no F where a model fits exactly, a mean of nothing): null (strict JSON)
    return [{k: _strict(row[k]) for k in keys} for row in rows]


def to_json(analysis: Analysis) -> dict[str, Any]:
    return {
        "data_source": analysis.source.to_dict(),
        "methods": methods_json(analysis),
        "comparisons": _records(analysis.comparison_rows, COMPARISON_KEYS),
        "mixed_anova": _records(analysis.anova_rows, ANOVA_KEYS),
        "lmm": _records(analysis.lmm_rows, LMM_KEYS),
        "descriptives": _records(analysis.descriptive_rows, DESCRIPTIVE_KEYS),
        "exclusions": analysis.exclusions,
        "warnings": analysis.warnings,
        "design_checks": _records(analysis.design_checks, CHECK_COLUMNS),
        "design_fit": _records(analysis.design_fit, FIT_COLUMNS),
        "success": _records(analysis.success_rows, SUCCESS_COLUMNS),
    }


def _write_set(analysis: Analysis, folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / "methods.md"]
    paths[0].write_text(methods_markdown(analysis))
    for table in all_tables(analysis):
        paths += table.write(folder, analysis.source.label)
    return paths


TESTS_COLUMNS = tuple(
    dict.fromkeys(
        [*COMPARISON_COLUMNS, "analysis", *ANOVA_COLUMNS, *LMM_COLUMNS, "note", "data_source"]
    )
)
"""tests.csv: every test, exclusion and note, the columns of the three tables joined."""


def write(analysis: Analysis, out_dir: Path, json_path: Path | None) -> list[Path]:
    paths = _write_set(analysis, out_dir)
    label = analysis.source.label
    tests = [
        *({**r, "analysis": "paired comparison"} for r in analysis.comparison_rows),
        *({**r, "analysis": "mixed ANOVA"} for r in analysis.anova_rows),
        *({**r, "analysis": "linear mixed model"} for r in analysis.lmm_rows),
        # the exclusions and notes travel with the tests
        *({"analysis": "exclusion", "note": n} for n in analysis.exclusions),
        *({"analysis": "note", "note": n} for n in analysis.warnings),
    ]
    write_csv(out_dir / "tests.csv", TESTS_COLUMNS, [{**r, "data_source": label} for r in tests])
    target = json_path or out_dir / "analysis.json"
    target.write_text(json.dumps(to_json(analysis), indent=2) + "\n")
    paths += [out_dir / "tests.csv", target]
    tasks = analysis.tasks
    if len(tasks) > 1:
        for task in tasks:
            paths += _write_set(analysis.for_task(task), out_dir / task)
    return paths
