"""The crossover's checks through `study import` and `study analyze`: a planted period
effect and carry-over are found and added, the first-period comparison is reported,
and methods.md says what was checked and found; a study without them adds nothing."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from study.cli import main
from study.protocol.design import TEMPLATE
from tests.study.crossover_csv import crossover_trials


def _analyze(tmp_path: Path, seed: int, period: float, carry_over: float) -> dict[str, Any]:
    crossover_trials(seed, period=period, carry_over=carry_over).to_csv(
        tmp_path / "t.csv", index=False
    )
    (tmp_path / "d.toml").write_text(TEMPLATE)
    db = str(tmp_path / "s.db")
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    assert main(["import", "--trials", str(tmp_path / "t.csv"), "--enrol-new", "--db", db]) == 0
    assert main(["analyze", "--db", db, "--out", str(tmp_path / "a")]) == 0
    out: dict[str, Any] = json.loads((tmp_path / "a" / "analysis.json").read_text())
    out["methods"] = (tmp_path / "a" / "methods.md").read_text()
    return out


def test_a_planted_period_and_carry_over_are_added(tmp_path: Path) -> None:
    result = _analyze(tmp_path, seed=0, period=0.1, carry_over=0.2)
    checks = {
        c["effect"]: c for c in result["design_checks"] if c["measure"] == "completion_time_s"
    }
    for effect in ("period", "carry_over"):
        assert checks[effect]["p_holm"] < 0.05, effect
        assert checks[effect]["added"] is True, effect
        for key in ("condition_before", "condition_after"):
            assert set(checks[effect][key]) >= {"estimate", "ci", "p", "df"}
    assert checks["trial_position"]["added"] is False
    fit = next(f for f in result["design_fit"] if f["measure"] == "completion_time_s")
    assert fit["added"] == ["period", "carry_over"]
    assert fit["first_period"]["participants"] == 36
    assert "first period only (36 participants, between participants)" in result["methods"]
    assert "called for a term" in result["methods"]


def test_a_study_without_them_adds_nothing(tmp_path: Path) -> None:
    result = _analyze(tmp_path, seed=1, period=0.0, carry_over=0.0)
    assert result["design_checks"]
    assert not any(c["added"] for c in result["design_checks"])
    assert all(f["first_period"] is None for f in result["design_fit"])
    assert "the model was kept as it was" in result["methods"]


def test_design_checks_csv_holds_one_number_per_cell(tmp_path: Path) -> None:
    """The CSV a reviewer reads into R: intervals and the condition effect before and
    after spread over columns of their own, each equal to analysis.json's value."""
    import csv

    result = _analyze(tmp_path, seed=0, period=0.1, carry_over=0.2)
    with (tmp_path / "a" / "design_checks.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(result["design_checks"])
    for row, check in zip(rows, result["design_checks"], strict=True):
        assert not any(v.startswith(("{", "[")) for v in row.values())
        assert float(row["ci_low"]) == check["ci"][0]
        assert float(row["ci_high"]) == check["ci"][1]
        for when in ("before", "after"):
            effect = check[f"condition_{when}"]
            assert float(row[f"condition_{when}_estimate"]) == effect["estimate"]
            assert float(row[f"condition_{when}_ci_high"]) == effect["ci"][1]
            assert float(row[f"condition_{when}_df"]) == effect["df"]
        assert row["data_source"] == result["data_source"]["label"]
