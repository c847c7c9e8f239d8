"""Imports that reconcile with enrolment and the schedule."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from db.engine import make_engine
from db.models.study import Participant, ScheduleBlock
from db.models.trial import Trial
from study.cli import main
from study.protocol.export import trial_columns
from study.protocol.session import pending_trials

DESIGN = """\
name = "reconcile"
seed = 2
tasks = ["lcca", "notes"]
trials_per_condition = 3
practice_trials = 1
[groups]
novice = 4
expert = 4
"""
HEADER = ",".join(trial_columns(["lcca", "notes"]))
"""Both tasks' measures, each under its own name: LCCA's two peaks, then NOTES's."""


def _init(tmp_path: Path, db: str, enrol: int = 2) -> None:
    (tmp_path / "d.toml").write_text(DESIGN)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    for _ in range(enrol):
        assert main(["participant", "add", "--group", "novice", "--db", db]) == 0


def _import(tmp_path: Path, db: str, rows: str, name: str = "t.csv") -> int:
    (tmp_path / name).write_text(HEADER + "\n" + rows)
    return main(["import", "--enrol-new", "--trials", str(tmp_path / name), "--db", db])


def test_an_imported_code_does_not_collide_with_enrolment(
    db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _init(tmp_path, db_url)
    assert _import(tmp_path, db_url, "P004,novice,lcca,VO,1,31.5,0.81,0.42,,,true\n") == 0
    capsys.readouterr()
    # novice's target is 4: P001, P002 and the imported P004 leave room for one
    add = ["participant", "add", "--group", "novice", "--db", db_url]
    assert main(add) == 0
    out = capsys.readouterr().out.split()
    assert main(add) == 2  # a fifth novice: past the target
    assert "has 4 of its 4 enrolled; expected at most 0" in capsys.readouterr().err
    assert main([*add, "--beyond-target"]) == 0
    # after P001, P002 and the imported P004: P005 and P006 (gaps are not reused)
    out += capsys.readouterr().out.split()
    assert [w for w in out if w.startswith("P0")] == ["P005", "P006"]


def _order(db: str, code: str) -> list[str]:
    engine = make_engine(db)
    with Session(engine) as s:
        order = s.scalars(select(Participant.condition_order).where(Participant.code == code)).one()
    engine.dispose()
    return list(order)


def test_imported_trials_land_in_the_block_of_their_task_and_condition(
    db_url: str, tmp_path: Path
) -> None:
    _init(tmp_path, db_url)
    code = next(c for c in ("P001", "P002") if _order(db_url, c)[0] == "HV")
    rows = (
        f"{code},novice,lcca,VO,1,31.5,0.81,0.42,,,true\n"
        f"{code},novice,notes,HV,2,40.0,,,3.10,1.20,false\n"
        "P007,expert,lcca,HV,1,22.0,0.70,0.30,,,true\n"
        "P007,expert,notes,HV,1,50.0,,,4.00,2.00,true\n"
    )
    assert _import(tmp_path, db_url, rows) == 0
    engine = make_engine(db_url)
    with Session(engine) as s:
        p = s.scalars(select(Participant).where(Participant.code == code)).one()
        blocks = {b.block_index: (b.task, b.condition) for b in p.blocks}
        filed = s.execute(
            select(Trial.task, Trial.condition, Trial.block_index, Trial.block_id)
            .where(Trial.participant_id == p.id)
            .order_by(Trial.id)
        ).all()
        for task, condition, block_index, block_id in filed:
            assert blocks[block_index] == (task, condition)
            block = s.get(ScheduleBlock, block_id)
            assert block is not None
            assert (block.task, block.condition) == (task, condition)
        # the session runs the other trials of those blocks, not one too few elsewhere
        todo = {
            (t.block.task, t.block.condition, t.practice, t.trial_index)
            for t in pending_trials(s, p)
        }
        assert ("lcca", "VO", False, 0) not in todo
        assert ("lcca", "HV", False, 0) in todo
        assert ("notes", "HV", False, 1) not in todo
        assert len(todo) == 4 * 4 - 2
        # the participant known only from the import: one block index per task x condition
        p7 = s.scalars(select(Participant).where(Participant.code == "P007")).one()
        indexes = s.scalars(select(Trial.block_index).where(Trial.participant_id == p7.id)).all()
        assert len(set(indexes)) == 2
    engine.dispose()
    assert main(["export", "--out", str(tmp_path / "out"), "--db", db_url]) == 0
    exported = pd.read_csv(tmp_path / "out" / "trials.csv")
    assert len(exported) == 4
    mine = exported[exported.participant == code].sort_values("task")
    assert mine[["task", "condition", "trial"]].values.tolist() == [
        ["lcca", "VO", 1],
        ["notes", "HV", 2],
    ]
    # each task's measures under its own names, the other task's left empty
    notes = mine[mine.task == "notes"].iloc[0]
    assert (notes["peak_force_demanded_n"], notes["peak_tip_force_n"]) == (3.10, 1.20)
    assert pd.isna(notes["peak_proximal_force_n"])
    assert pd.isna(notes["peak_distal_force_n"])
    lcca = mine[mine.task == "lcca"].iloc[0]
    assert (lcca["peak_proximal_force_n"], lcca["peak_distal_force_n"]) == (0.81, 0.42)
    assert pd.isna(lcca["peak_force_demanded_n"])


def test_the_same_file_imported_twice_is_refused_with_one_line(
    db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _init(tmp_path, db_url)
    rows = (
        "P001,novice,lcca,VO,1,31.5,0.81,0.42,,,true\nP009,expert,lcca,HV,2,22.0,0.7,0.3,,,true\n"
    )
    assert _import(tmp_path, db_url, rows) == 0
    capsys.readouterr()
    assert _import(tmp_path, db_url, rows) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "row 2, column trial" in err[0], err
    assert "already stored" in err[0], err
    engine = make_engine(db_url)
    with Session(engine) as s:
        assert s.scalar(select(func.count()).select_from(Trial)) == 2
    engine.dispose()
