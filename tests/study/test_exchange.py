"""`study import` / `study export`: the column contracts, all-or-nothing imports."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from sqlalchemy import create_engine, func, select
from sqlalchemy.orm import Session

from db.models.trial import Trial
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.exchange import (
    PROVENANCE_COLUMNS,
    TLX_COLUMNS,
    TLX_PROVENANCE_COLUMNS,
    TLX_WEIGHT_COLUMNS,
    TRIAL_COLUMNS,
)

TRIALS = (
    ",".join(TRIAL_COLUMNS)
    + """
P001,novice,lcca,VO,1,31.5,0.81,0.42,true
P001,novice,lcca,HV,1,35.0,0.55,0.18,true
P002,expert,lcca,VO,1,22.0,0.70,0.30,false
"""
)
TLX = (
    ",".join(TLX_COLUMNS + TLX_WEIGHT_COLUMNS)
    + """
P001,lcca,VO,70,20,50,30,60,40,5,0,3,2,4,1
P001,lcca,HV,50,20,40,30,45,25,5,0,3,2,4,1
"""
)


def _init(tmp_path: Path, name: str) -> str:
    db = str(tmp_path / name)
    (tmp_path / "d.toml").write_text(TEMPLATE)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    return db


def _count_trials(db: str) -> int:
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        n = s.scalar(select(func.count()).select_from(Trial))
    engine.dispose()
    return n


def test_import_then_export_round_trips_the_contract(db_url: str, tmp_path: Path) -> None:
    db = db_url
    (tmp_path / "d.toml").write_text(TEMPLATE)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    (tmp_path / "t.csv").write_text(TRIALS)
    (tmp_path / "x.csv").write_text(TLX)
    argv = [
        "import",
        "--enrol-new",
        "--trials",
        str(tmp_path / "t.csv"),
        "--tlx",
        str(tmp_path / "x.csv"),
    ]
    assert main([*argv, "--db", db]) == 0
    assert main(["export", "--out", str(tmp_path / "out"), "--db", db]) == 0
    trials = pd.read_csv(tmp_path / "out" / "trials.csv")
    assert tuple(trials.columns) == TRIAL_COLUMNS + PROVENANCE_COLUMNS
    assert set(trials["driver"]) == {"imported"}
    assert set(trials["data_source"]) == {"measured"}
    pd.testing.assert_frame_equal(
        trials[list(TRIAL_COLUMNS)]
        .sort_values(["participant", "condition"])
        .reset_index(drop=True),
        pd.read_csv(tmp_path / "t.csv")
        .sort_values(["participant", "condition"])
        .reset_index(drop=True),
    )
    tlx = pd.read_csv(tmp_path / "out" / "tlx.csv")
    assert tuple(tlx.columns) == TLX_COLUMNS + TLX_WEIGHT_COLUMNS + TLX_PROVENANCE_COLUMNS
    assert tlx["w_mental"].tolist() == [5, 5]
    codebook = pd.read_csv(tmp_path / "out" / "codebook.csv")
    assert set(trials.columns) | set(tlx.columns) <= set(codebook["column"])
    assert codebook.set_index("column").loc["peak_distal_force_n", "unit"] == "N"


@pytest.mark.parametrize(
    "row, message",
    [
        ("P003,novice,lcca,VO,1,31.5,-0.2,0.42,true", "row 5, column peak_proximal_force_n"),
        ("P003,surgeon,lcca,VO,1,31.5,0.2,0.42,true", "row 5, column group: 'surgeon'"),
        ("P003,novice,lcca,XX,1,31.5,0.2,0.42,true", "row 5, column condition"),
        ("Alice,novice,lcca,VO,1,31.5,0.2,0.42,true", "row 5, column participant"),
        ("P003,novice,lcca,VO,1,31.5,0.2,0.42,maybe", "row 5, column success"),
        ("P001,novice,lcca,VO,1,31.5,0.2,0.42,true", "row 5, column trial: repeats row 2"),
        ("P002,novice,lcca,HV,1,31.5,0.2,0.42,true", "row 5, column group: 'novice' but P002"),
    ],
)
def test_a_bad_row_is_named_and_nothing_is_written(
    row: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = _init(tmp_path, "b.db")
    (tmp_path / "t.csv").write_text(TRIALS + row + "\n")
    capsys.readouterr()
    assert main(["import", "--enrol-new", "--trials", str(tmp_path / "t.csv"), "--db", db]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert message in err[0]
    assert _count_trials(db) == 0


def test_an_off_scale_tlx_row_refuses_the_whole_import(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = _init(tmp_path, "c.db")
    (tmp_path / "t.csv").write_text(TRIALS)
    (tmp_path / "x.csv").write_text(TLX.replace("70,20,50", "70,22,50"))
    capsys.readouterr()
    argv = [
        "import",
        "--enrol-new",
        "--trials",
        str(tmp_path / "t.csv"),
        "--tlx",
        str(tmp_path / "x.csv"),
    ]
    assert main([*argv, "--db", db]) == 2
    assert (
        "row 2, column physical: physical rating 22.0 is off the scale" in capsys.readouterr().err
    )
    assert _count_trials(db) == 0


def test_a_missing_column_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = _init(tmp_path, "d.db")
    (tmp_path / "t.csv").write_text(TRIALS.replace(",success", ",ok"))
    capsys.readouterr()
    assert main(["import", "--enrol-new", "--trials", str(tmp_path / "t.csv"), "--db", db]) == 2
    assert "lacks column 'success'" in capsys.readouterr().err


def test_parquet_export_has_the_same_columns(tmp_path: Path) -> None:
    db = _init(tmp_path, "e.db")
    (tmp_path / "t.csv").write_text(TRIALS)
    assert main(["import", "--enrol-new", "--trials", str(tmp_path / "t.csv"), "--db", db]) == 0
    assert main(["export", "--out", str(tmp_path / "pq"), "--format", "parquet", "--db", db]) == 0
    columns = tuple(pd.read_parquet(tmp_path / "pq" / "trials.parquet").columns)
    assert columns == TRIAL_COLUMNS + PROVENANCE_COLUMNS


def test_the_column_contracts_are_the_issues() -> None:
    assert TRIAL_COLUMNS == (
        "participant",
        "group",
        "task",
        "condition",
        "trial",
        "completion_time_s",
        "peak_proximal_force_n",
        "peak_distal_force_n",
        "success",
    )
    assert TLX_COLUMNS == (
        "participant",
        "task",
        "condition",
        "mental",
        "physical",
        "temporal",
        "performance",
        "effort",
        "frustration",
    )
    assert TLX_WEIGHT_COLUMNS == tuple(
        f"w_{s}" for s in ("mental", "physical", "temporal", "performance", "effort", "frustration")
    )
