"""The NOTES measures the surgeons' benchmark compares ([notes], IV), on hand-built
traces, and the benchmark's summary against hand-computed statistics."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.bench.notes_surgeons import PAPER, surgeons_summary
from study.tasks.notes.trial import measures


def _trace(force: list[float], torque: list[float]) -> pd.DataFrame:
    n = len(force)
    return pd.DataFrame(
        {
            "t_s": 0.01 * np.arange(1, n + 1),
            "force_demanded_n": force,
            "force_rendered_n": np.clip(force, -5.62, 5.62),
            "torque_demanded_n_m": torque,
            "torque_rendered_n_m": torque,
            "tip_force_n": np.zeros(n),
        }
    )


def test_measures_of_a_hand_built_trace() -> None:
    # ten samples: pushes up to 9.9 N (three of them above 5.62 N, one exactly at it),
    # pulls down to -4.5 N; torques up to +76.7 and -85 N mm
    force = [0.0, 3.0, 5.62, 6.0, 9.9, 7.0, 2.0, -1.0, -4.5, -3.0]
    torque = [0.0, 0.02, 0.0767, 0.05, 0.0, -0.03, -0.085, -0.06, 0.01, 0.0]
    m = measures(_trace(force, torque), success=True)
    assert m["peak_push_n"] == 9.9
    assert m["peak_pull_n"] == 4.5
    assert m["peak_torque_cw_n_m"] == 0.0767
    assert m["peak_torque_ccw_n_m"] == 0.085
    # strictly above the device's 5.62 N: 6.0, 9.9, 7.0 of ten samples
    assert m["push_over_capacity_fraction"] == pytest.approx(0.3)
    assert m["peak_force_demanded_n"] == 9.9
    assert m["peak_torque_demanded_n_m"] == 0.085


def test_a_trace_that_never_pulls_has_no_pull() -> None:
    m = measures(_trace([1.0, 2.0, 6.0], [0.01, 0.02, 0.03]), success=False)
    assert m["peak_pull_n"] == 0.0
    assert m["peak_torque_ccw_n_m"] == 0.0
    assert m["push_over_capacity_fraction"] == pytest.approx(1 / 3)


def test_surgeons_summary_is_mean_sd_and_range_beside_the_paper() -> None:
    trials = pd.DataFrame(
        {
            "peak_push_n": [9.0, 10.0, 11.0],
            "peak_pull_n": [4.0, 4.5, 5.0],
            "peak_torque_cw_n_m": [0.07, 0.08, 0.09],
            "peak_torque_ccw_n_m": [0.06, 0.07, 0.08],
            "push_over_capacity_fraction": [0.20, 0.25, 0.30],
        }
    )
    s = surgeons_summary(trials).set_index("measure")
    # mean of 9, 10, 11 is 10; SD (ddof 1) sqrt((1 + 0 + 1) / 2) = 1
    assert s.loc["peak_push_n", "mean"] == pytest.approx(10.0)
    assert s.loc["peak_push_n", "sd"] == pytest.approx(1.0)
    assert (s.loc["peak_push_n", "min"], s.loc["peak_push_n", "max"]) == (9.0, 11.0)
    assert s.loc["peak_torque_cw_n_m", "sd"] == pytest.approx(0.01)
    # |10 - 9.9| <= 1: within; CCW |0.07 - 0.085| = 0.015 > 0.010: not
    assert s.loc["peak_push_n", "within_target"]
    assert not s.loc["peak_torque_ccw_n_m", "within_target"]
    assert s.loc["push_over_capacity_fraction", "paper"] == 0.2357
    assert set(s.index) == set(PAPER)
    assert (s["n"] == 3).all()


def test_bench_notes_reports_the_surgeons_benchmark(tmp_path: Path) -> None:
    from study.cli import main

    out = tmp_path / "out"
    argv = ["bench", "notes", "--json", str(tmp_path / "n.json"), "--out", str(out)]
    assert main([*argv, "--draws", "1", "--trials", "1", "--surgeons", "2"]) == 0
    report = json.loads((tmp_path / "n.json").read_text())["surgeons_benchmark"]
    assert "simulated" in report["source"]
    assert report["condition"] == "VO"
    people = pd.DataFrame(report["participants"])
    vo = people[people["condition"] == "VO"]
    for row in report["summary"]:
        assert row["mean"] == pytest.approx(vo[row["measure"]].mean())
        assert row["n"] == 2
        assert math.isfinite(row["sd"])
    assert "SIMULATED experts" in (out / "notes_bench.md").read_text()
    assert len(pd.read_csv(out / "notes_surgeons.csv")) == 4
