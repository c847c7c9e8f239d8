"""`study export` then `study import` into a new database: every row back, the block
order, the simulated label, the questionnaires without pairwise choices, and the same
analysis; an export from before the provenance columns still imports."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
from sqlalchemy import create_engine, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import Trial
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.exchange import PROVENANCE_COLUMNS, TLX_COLUMNS, TRIAL_COLUMNS
from tests.study.crossover_csv import crossover_trials


def _init(tmp_path: Path, name: str) -> str:
    (tmp_path / "d.toml").write_text(TEMPLATE)
    db = str(tmp_path / name)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    return db


def _tlx(trials: pd.DataFrame) -> pd.DataFrame:
    """One questionnaire per block; every second one without the pairwise choices."""
    blocks = trials.drop_duplicates(["participant", "condition"])
    rows = []
    for i, (code, condition) in enumerate(
        zip(blocks["participant"], blocks["condition"], strict=True)
    ):
        weights = ["5", "0", "3", "2", "4", "1"] if i % 2 else [""] * 6
        ratings = [str(5 * ((i + k) % 21)) for k in range(6)]
        rows.append([code, "lcca", condition, *ratings, *weights])
    columns = [*TLX_COLUMNS, *(f"w_{s}" for s in TLX_COLUMNS[3:])]
    return pd.DataFrame(rows, columns=columns)


def _orders(db: str) -> dict[str, list[str]]:
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        out = {p.code: list(p.condition_order) for p in s.scalars(select(Participant))}
        drivers = set(s.scalars(select(Trial.driver)))
    engine.dispose()
    return {**out, "drivers": sorted(d or "" for d in drivers)}


def test_an_export_imports_back_with_the_same_analysis(tmp_path: Path) -> None:
    source = crossover_trials(seed=3)
    source.to_csv(tmp_path / "t.csv", index=False)
    _tlx(source).to_csv(tmp_path / "x.csv", index=False)
    first = _init(tmp_path, "first.db")
    files = ["--trials", str(tmp_path / "t.csv"), "--tlx", str(tmp_path / "x.csv")]
    assert main(["import", *files, "--enrol-new", "--db", first]) == 0
    out = tmp_path / "exp"
    assert main(["export", "--out", str(out), "--db", first]) == 0
    exported = pd.read_csv(out / "trials.csv", dtype=str, keep_default_na=False)
    assert tuple(exported.columns) == (*TRIAL_COLUMNS, *PROVENANCE_COLUMNS)
    assert set(exported["data_source"]) == {"simulated"}
    assert set(exported["included"]) == {"yes"}
    tlx = pd.read_csv(out / "tlx.csv", dtype=str, keep_default_na=False)
    assert (tlx["w_mental"] == "").sum() == 36  # the choice-less half, exported empty

    second = _init(tmp_path, "second.db")
    files = ["--trials", str(out / "trials.csv"), "--tlx", str(out / "tlx.csv")]
    assert main(["import", *files, "--enrol-new", "--db", second]) == 0
    orders = _orders(second)
    assert orders == _orders(first)
    assert orders["P002"] == ["HV", "VO"]
    assert orders["drivers"] == ["simulated"]
    again = tmp_path / "exp2"
    assert main(["export", "--out", str(again), "--db", second]) == 0
    for name in ("trials.csv", "tlx.csv"):
        assert (again / name).read_text() == (out / name).read_text()

    results = []
    for db, folder in ((first, "a1"), (second, "a2")):
        assert main(["analyze", "--db", db, "--out", str(tmp_path / folder)]) == 0
        results.append(json.loads((tmp_path / folder / "analysis.json").read_text()))
        methods = (tmp_path / folder / "methods.md").read_text()
        assert "simulated" in methods.lower()
    for key in ("comparisons", "lmm", "design_checks", "data_source"):
        assert results[0][key] == results[1][key], key
    assert results[1]["data_source"]["trials_by_driver"]["simulated"] == len(source)


def test_an_export_from_before_the_provenance_columns_imports_as_measured(
    tmp_path: Path,
) -> None:
    old = crossover_trials(seed=4)[list(TRIAL_COLUMNS)].head(12)
    old.to_csv(tmp_path / "t.csv", index=False)
    db = _init(tmp_path, "old.db")
    assert main(["import", "--trials", str(tmp_path / "t.csv"), "--enrol-new", "--db", db]) == 0
    orders = _orders(db)
    # no block column: the design's order; no driver column: imported (measured)
    assert orders["P001"] == ["VO", "HV"]
    assert orders["P002"] == ["VO", "HV"]
    assert orders["drivers"] == ["imported"]
