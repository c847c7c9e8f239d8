"""`study export` files are safe to open in a spreadsheet, replaced atomically and never
written through a symbolic link."""

from __future__ import annotations

import csv
import errno
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pytest

from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.exchange import TRIAL_COLUMNS
from study.protocol.export_files import escape_array, escape_cell, unescape_cell

EVIL = '=HYPERLINK("http://e.x","y")'
TRIALS = (
    ",".join(TRIAL_COLUMNS)
    + f"""
P001,"{EVIL.replace('"', '""')}",lcca,VO,1,31.5,0.81,0.42,true
P002,expert,lcca,VO,1,22.0,0.70,0.30,false
"""
)


def _design(tmp_path: Path) -> Path:
    # a design whose group name is a formula: the way such text reaches an export
    path = tmp_path / "d.toml"
    path.write_text(TEMPLATE.replace("novice = 8", '"=HYPERLINK(\\"http://e.x\\",\\"y\\")" = 8'))
    return path


def _study(tmp_path: Path, db: str) -> None:
    assert main(["init", "--design", str(_design(tmp_path)), "--db", db]) == 0
    (tmp_path / "t.csv").write_text(TRIALS)
    assert main(["import", "--enrol-new", "--trials", str(tmp_path / "t.csv"), "--db", db]) == 0


@pytest.mark.parametrize(
    "cell, escaped",
    [
        (EVIL, "'" + EVIL),
        ("+A1", "'+A1"),
        ("-A1+1", "'-A1+1"),
        ("@SUM(A1)", "'@SUM(A1)"),
        ("\tx", "'\tx"),
        ("\rx", "'\rx"),
        ("-0.5", "-0.5"),  # a number, not a formula
        ("+1e3", "+1e3"),
        ("novice", "novice"),
        ("", ""),
        (-0.5, -0.5),
    ],
)
def test_formula_like_text_gets_a_quote_and_numbers_do_not(cell: object, escaped: object) -> None:
    assert escape_cell(cell) == escaped
    if isinstance(cell, str):
        assert unescape_cell(escaped) == cell  # type: ignore[arg-type]
    arrow = escape_array(pa.array([cell] if isinstance(cell, str) else [str(cell)]))
    assert arrow.to_pylist() == [escaped if isinstance(cell, str) else str(cell)]


def test_an_imported_formula_comes_out_escaped_and_imports_back(
    db_url: str, tmp_path: Path
) -> None:
    _study(tmp_path, db_url)
    out = tmp_path / "out"
    assert main(["export", "--out", str(out), "--db", db_url]) == 0
    with open(out / "trials.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert {r["group"] for r in rows} == {"'" + EVIL, "expert"}
    assert not any(v.startswith(("=", "+", "@")) for r in rows for v in r.values())
    # the escaped file is a faithful export: a fresh study imports it back as it was
    again = tmp_path / "again"
    again.mkdir()
    db2 = str(tmp_path / "again.db")
    assert main(["init", "--design", str(_design(again)), "--db", db2]) == 0
    assert main(["import", "--enrol-new", "--trials", str(out / "trials.csv"), "--db", db2]) == 0
    assert main(["export", "--out", str(again / "out"), "--db", db2]) == 0
    assert (again / "out" / "trials.csv").read_bytes() == (out / "trials.csv").read_bytes()


@pytest.mark.parametrize("name", ["codebook.csv", "trials.csv"])
def test_a_symlinked_target_is_refused_and_its_file_untouched(
    tmp_path: Path, name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    db = str(tmp_path / "s.db")
    _study(tmp_path, db)
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    (out / name).symlink_to(victim)
    capsys.readouterr()
    assert main(["export", "--out", str(out), "--db", db]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert str(out / name) in err[0]
    assert "symbolic link" in err[0]
    assert victim.read_text() == "precious\n"
    assert (out / name).is_symlink()
    assert sorted(p.name for p in out.iterdir()) == [name]  # nothing else written


def test_an_interrupted_export_leaves_the_previous_files(
    db_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _study(tmp_path, db_url)
    out = tmp_path / "out"
    assert main(["export", "--out", str(out), "--db", db_url]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    # more data, so that a finished export would differ from the files on disk
    (tmp_path / "t2.csv").write_text(
        ",".join(TRIAL_COLUMNS) + "\nP002,expert,lcca,VO,2,25.0,0.5,0.2,true\n"
    )
    assert (
        main(["import", "--enrol-new", "--trials", str(tmp_path / "t2.csv"), "--db", db_url]) == 0
    )
    real = pd.DataFrame.to_csv
    calls = []

    def full_disk(self: pd.DataFrame, target: object, *args: object, **kwargs: object) -> None:
        calls.append(target)
        if len(calls) == 2:  # the tlx file: half of it, then the disk is full
            target.write(b"participant,task,")  # type: ignore[attr-defined]
            raise OSError(errno.ENOSPC, "No space left on device")
        real(self, target, *args, **kwargs)

    monkeypatch.setattr(pd.DataFrame, "to_csv", full_disk)
    capsys.readouterr()
    assert main(["export", "--out", str(out), "--db", db_url]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "No space left on device" in err[0]
    assert str(out) in err[0]
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # no .partial either
    monkeypatch.undo()
    assert main(["export", "--out", str(out), "--db", db_url]) == 0
    assert len(pd.read_csv(out / "trials.csv")) == 3


def test_a_symlinked_per_trial_samples_file_is_refused_before_any_is_written(
    tmp_path: Path,
) -> None:
    from db.migrate import open_database
    from study.protocol.export_files import ExportTargetError
    from study.protocol.sample_export import ExportTrial, write_samples_per_trial

    db = str(tmp_path / "s.db")
    _study(tmp_path, db)
    trials = [ExportTrial(k, "P001", "lcca", "VO", k, 1) for k in (1, 2)]
    folder = tmp_path / "samples"
    folder.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    (folder / f"{trials[1].file_stem}.csv").symlink_to(victim)
    engine = open_database(db, create=False)
    try:
        with pytest.raises(ExportTargetError, match="symbolic link"):
            write_samples_per_trial(engine, trials, folder, "csv")
    finally:
        engine.dispose()
    assert victim.read_text() == "precious\n"
    assert [p.name for p in folder.iterdir()] == [f"{trials[1].file_stem}.csv"]


def test_an_analysis_table_csv_escapes_a_formula_group_and_keeps_negative_numbers(
    tmp_path: Path,
) -> None:
    from study.analysis.tables import Table

    raw = [{"group": EVIL, "hedges_g": -0.5}, {"group": "novice", "hedges_g": 0.25}]
    cells = [[r["group"], r["hedges_g"]] for r in raw]
    columns = ("group", "hedges_g")
    table = Table("comparisons", columns, raw, columns, cells, "caption")
    csv_path = table.write(tmp_path, "simulated")[0]
    with open(csv_path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["group"] for r in rows] == ["'" + EVIL, "novice"]
    assert [r["hedges_g"] for r in rows] == ["-0.5", "0.25"]
