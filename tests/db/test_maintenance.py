"""The end-of-day check and backup (`db.maintenance`, `study db check|backup`) on both
backends: the copy is a study database holding every row and sample of the source, and
a damaged SQLite file is named as such, not copied."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import Engine, select

from db.maintenance import backup_database, check_database
from db.migrate import inspect_database, open_database
from db.sample_reader import SampleReader
from db.samples import SampleWriter
from study.cli import main
from tests.db.test_samples import SCHEMA, _trial


def _with_samples(engine: Engine) -> tuple[int, np.ndarray]:
    trial_id = _trial(engine)
    t = np.arange(250) / 100.0  # 2.5 s at 100 Hz: three chunks
    with SampleWriter(engine, trial_id, schema=SCHEMA) as out:
        out.extend({"t_s": t, "proximal_force_n": np.cos(t)})
    return trial_id, t


def _rows(engine: Engine) -> dict[str, list[tuple]]:
    from db.maintenance import _tables

    with engine.connect() as conn:
        return {
            t.name: [tuple(r) for r in conn.execute(select(t).order_by(*t.primary_key.columns))]
            for t in _tables()
        }


def test_check_and_backup_copy_every_row_and_sample(engine: Engine, tmp_path: Path) -> None:
    trial_id, t = _with_samples(engine)
    check = check_database(engine)
    assert check.ok, check.problems
    # the rows counted are those `study db info` counts
    info = inspect_database(engine.url)
    assert {k: v for k, v in info.row_counts.items() if k in check.rows} == check.rows
    assert check.rows["sample_chunks"] == 3
    assert check.rows["participants"] == 1
    assert check.line().endswith(f"integrity ok (14 tables, {sum(check.rows.values()):,} rows)")

    result = backup_database(engine, tmp_path / "backups", replace_file=os.replace)
    assert result.copy.ok
    assert result.copy.rows == check.rows
    assert result.path.parent == tmp_path / "backups"
    assert result.path.suffix == ".db"
    assert sorted(p.name for p in result.path.parent.iterdir()) == [result.path.name]
    copy = open_database(str(result.path), create=False)
    try:
        source_rows, copy_rows = _rows(engine), _rows(copy)
        assert copy_rows.keys() == source_rows.keys()
        for name, rows in source_rows.items():
            # datetimes come back naive from SQLite: compared as text without the zone
            def plain(row):
                return tuple(
                    v.replace(tzinfo=None) if hasattr(v, "tzinfo") and v.tzinfo else v for v in row
                )

            assert [plain(r) for r in copy_rows[name]] == [plain(r) for r in rows], name
        with SampleReader(copy) as reader:
            stored = np.concatenate([b.column("t_s").to_numpy() for b in reader.trial(trial_id)])
        np.testing.assert_array_equal(stored, t)
    finally:
        copy.dispose()
    # one line: the check, the copy, its size and digest, the copy's check
    assert result.line().startswith(check.line() + f"; copy {result.path} (")
    assert result.line().endswith(f"sha256 {result.sha256[:12]}) checked ok")


@pytest.fixture
def sqlite_study(tmp_path: Path) -> Path:
    db = tmp_path / "study.db"
    engine = open_database(str(db), create=True)
    _with_samples(engine)
    engine.dispose()
    return db


def _damage_an_index(db: Path) -> None:
    """Overwrite the root page of an index with other bytes: the table is intact, its
    index no longer matches it."""
    raw = sqlite3.connect(db)
    page_size = raw.execute("PRAGMA page_size").fetchone()[0]
    [(root,)] = raw.execute(
        "SELECT rootpage FROM sqlite_master WHERE type = 'index' AND tbl_name = 'participants'"
        " AND sql IS NULL LIMIT 1"
    ).fetchall()
    raw.close()
    with db.open("r+b") as f:
        f.seek((root - 1) * page_size + 8)  # past the page header's first bytes
        f.write(b"\xff" * 64)


def test_a_damaged_sqlite_file_is_named_and_not_copied(sqlite_study: Path, tmp_path) -> None:
    _damage_an_index(sqlite_study)
    engine = open_database(str(sqlite_study), create=False)
    try:
        check = check_database(engine)
        assert not check.ok
        assert "integrity problem" in check.line()
        assert "\n" not in check.line()
        result = backup_database(engine, tmp_path / "backups", replace_file=os.replace)
    finally:
        engine.dispose()
    assert result.line() == check.line()
    assert not (tmp_path / "backups").exists()  # nothing written


def test_a_row_pointing_at_a_missing_one_is_found(sqlite_study: Path) -> None:
    raw = sqlite3.connect(sqlite_study)
    raw.execute("PRAGMA foreign_keys = OFF")
    raw.execute("INSERT INTO trial_measures (trial_id, name, value) VALUES (999, 'x', 1.0)")
    raw.commit()
    raw.close()
    engine = open_database(str(sqlite_study), create=False)
    try:
        check = check_database(engine)
    finally:
        engine.dispose()
    assert check.problems == ["trial_measures row 1 refers to a missing trials"]


def test_study_db_check_and_backup(sqlite_study: Path, tmp_path: Path, capsys) -> None:
    assert main(["db", "check", "--db", str(sqlite_study)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith(f"sqlite:///{sqlite_study}: integrity ok (14 tables, ")
    out = tmp_path / "copies"
    assert main(["db", "backup", "--db", str(sqlite_study), "--out", str(out)]) == 0
    line = capsys.readouterr().out.strip()
    [copy] = list(out.iterdir())
    assert f"; copy {copy} (" in line
    assert line.endswith("checked ok")
    _damage_an_index(sqlite_study)
    assert main(["db", "check", "--db", str(sqlite_study)]) == 1
    assert "integrity problem" in capsys.readouterr().out
    assert main(["db", "backup", "--db", str(sqlite_study), "--out", str(out)]) == 1
    assert list(out.iterdir()) == [copy]  # no second copy of a damaged file
