"""`study bench startup`: one tiny run end to end, and its sqlite3 reference."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from study.bench.db_write import bench_schema, scratch_database, scratch_trial, synthetic_columns
from study.bench.startup import _reference_insert, bench_demo
from study.cli import main


def test_the_sqlite3_reference_stores_the_rows_the_writer_is_handed(tmp_path: Path) -> None:
    columns = synthetic_columns(2500, 1000.0, seed=0)
    names = ("trial_id", "seq", *bench_schema().names)
    with scratch_database(None) as engine:
        trial_id = scratch_trial(engine)
        path = Path(engine.url.database)  # type: ignore[arg-type]
        engine.dispose()
        assert _reference_insert(path, trial_id, columns, names) > 0
        with sqlite3.connect(path) as conn:
            stored = conn.execute(
                "SELECT seq, t_s, dial_torque_n_m, tip_x_m FROM samples ORDER BY seq"
            ).fetchall()
    assert [r[0] for r in stored] == list(range(2500))
    assert [r[1] for r in stored] == columns["t_s"].tolist()
    assert [r[2] for r in stored] == columns["dial_torque_n_m"].tolist()
    assert {r[3] for r in stored} == {None}


def test_bench_startup_reports_every_figure_as_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "startup.json"
    argv = ["bench", "startup", "--runs", "1", "--rows", "2000", "--demo-runs", "0"]
    assert main([*argv, "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert set(result) == {
        "runs",
        "simulate",
        "simulate_trial_s",
        "run_screen",
        "analyze",
        "analyze_db",
        "writer",
        "demo",
        "load_average",
    }
    assert result["demo"] is None  # --demo-runs 0
    for figure in ("simulate", "run_screen", "analyze"):
        assert set(result[figure]) == {"seconds", "median_s", "target_s"}
        assert len(result[figure]["seconds"]) == 1
    assert result["simulate_trial_s"] == pytest.approx(30.0)
    writer = result["writer"]
    assert writer["rows"] == 2000
    assert len(writer["writer_rows_per_s"]) == 1
    assert writer["ratio"] == pytest.approx(
        writer["writer_rows_per_s"][0] / writer["sqlite3_rows_per_s"][0]
    )
    assert writer["ratio_foreign_keys"] == pytest.approx(
        writer["writer_rows_per_s"][0] / writer["sqlite3_foreign_keys_rows_per_s"][0]
    )
    assert "load average" in capsys.readouterr().out


def test_bench_demo_times_whole_demo_runs_in_fresh_processes(tmp_path: Path) -> None:
    timing = bench_demo(tmp_path, 1, ("--quick",))
    assert len(timing.seconds) == 1
    assert timing.target_s == 30.0
    # the warm-up and the counted run each built a whole study: database, analysis, figures
    for k in (0, 1):
        assert (tmp_path / f"demo{k}" / "demo.db").is_file()
        assert (tmp_path / f"demo{k}" / "analysis" / "analysis.json").is_file()
