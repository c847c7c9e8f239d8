"""Does the export how-to's R script reproduce `study analyze`? Every number both give,
compared on one study.

    python benchmarks/reproduce_check.py --db demo/demo.db \\
        --out benchmarks/results/reproduce_check.json

Exports the study (`study export`), runs `Rscript docs/how-to/reproduce.R` on the export
alone and `study analyze` on the database, then matches the rows of each R table with
`analysis.json` (comparisons and success by task, measure and group; the mixed model by
task, measure and term; the crossover's checks by task, measure and effect) and reports,
per table and column, the rows compared, the largest relative difference
(|a - b| / max(|b|, 1e-300)) and the rows where one side has a value and the other none.
Needs R with afex, lmerTest, emmeans, coin and BayesFactor.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent

# R table -> (analysis.json key, the key columns, R column -> JSON key)
TABLES: dict[str, tuple[str, tuple[str, ...], dict[str, str]]] = {
    "comparisons": (
        "comparisons",
        ("task", "measure", "group"),
        {
            c: c
            for c in (
                "n",
                "statistic",
                "p",
                "p_holm",
                "effect_size",
                "mean_diff",
                "diff_ci_low",
                "diff_ci_high",
                "dz",
                "dz_ci_low",
                "dz_ci_high",
                "g_av",
                "bf10",
            )
        },
    ),
    "success": (
        "success",
        ("task", "group"),
        {c: c for c in ("n", "success_vo", "success_hv", "vo_only", "hv_only", "p", "p_holm")},
    ),
    "design_checks": (
        "design_checks",
        ("task", "measure", "effect"),
        {"estimate": "estimate", "p": "p", "p_holm": "p_holm"},
    ),
}


def _number(value: Any) -> float | None:
    if value in (None, "", "NA"):
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(x) else x


def compare(r_dir: Path, analysis: dict[str, Any]) -> dict[str, Any]:
    """Per table and column: rows compared, the largest relative difference, and the
    rows where only one side has a number."""
    out: dict[str, Any] = {}
    for table, (key, keys, columns) in TABLES.items():
        path = r_dir / f"{table}.csv"
        if not path.exists():
            out[table] = {"missing": f"R wrote no {table}.csv"}
            continue
        with path.open(newline="") as f:
            r_rows = {tuple(row[k] for k in keys): row for row in csv.DictReader(f)}
        py_rows = {tuple(str(row[k]) for k in keys): row for row in analysis[key]}
        report: dict[str, Any] = {
            "rows_r": len(r_rows),
            "rows_python": len(py_rows),
            "rows_matched": len(r_rows.keys() & py_rows.keys()),
        }
        for r_col, py_col in columns.items():
            worst, compared, one_sided = 0.0, 0, []
            for k in r_rows.keys() & py_rows.keys():
                a, b = _number(r_rows[k][r_col]), _number(py_rows[k].get(py_col))
                if a is None and b is None:
                    continue
                if a is None or b is None:
                    one_sided.append("/".join(k))
                    continue
                compared += 1
                worst = max(worst, abs(a - b) / max(abs(b), 1e-300))
            report[r_col] = {"compared": compared, "max_rel_diff": worst, "one_sided": one_sided}
        out[table] = report
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", required=True)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    study = [sys.executable, "-m", "study.cli"]
    with tempfile.TemporaryDirectory() as tmp:
        export, r_out, py_out = Path(tmp) / "export", Path(tmp) / "r", Path(tmp) / "py"
        subprocess.run(
            [*study, "export", "--db", args.db, "--out", str(export)],
            check=True,
            capture_output=True,
        )
        subprocess.run(
            [
                "Rscript",
                str(HERE.parent / "docs" / "how-to" / "reproduce.R"),
                str(export),
                str(r_out),
            ],
            check=True,
            capture_output=True,
        )
        subprocess.run(
            [*study, "analyze", "--db", args.db, "--out", str(py_out)],
            check=True,
            capture_output=True,
        )
        analysis = json.loads((py_out / "analysis.json").read_text())
        report = {
            "command": " ".join(["python", "benchmarks/reproduce_check.py", *sys.argv[1:]]),
            "data_source": analysis["data_source"]["label"],
            "tables": compare(r_out, analysis),
        }
        report["max_rel_diff"] = max(
            (
                column["max_rel_diff"]
                for table in report["tables"].values()
                for column in table.values()
                if isinstance(column, dict)
            ),
            default=float("nan"),
        )
    text = json.dumps(report, indent=2) + "\n"
    if args.out:
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
