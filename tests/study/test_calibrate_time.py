"""`study bench calibrate --time`: its summary and table from given runs, and its refusals."""

from __future__ import annotations

from pathlib import Path

import pytest

from study.bench.calibrate_time import TARGET_S, _summary, markdown
from study.cli import main


def _run(recording: str, cpu_s: float, wall_s: float, load: float) -> dict:
    return {
        "recording": recording,
        "repeat": 1,
        "wall_s": wall_s,
        "cpu_s": cpu_s,
        "cpu_user_s": cpu_s,
        "load_average_1min_at_start": load,
        "effects_added": ["stribeck"] if recording == "stribeck" else [],
        "discovered_terms": [],
        "verdict": "white",
        "rmse_after": 0.03,
    }


def test_summary_takes_the_slowest_simulated_run_and_reads_the_target() -> None:
    runs = [
        _run("clean", 4.0, 20.0, 3.0),
        _run("stribeck", 6.5, 75.0, 12.0),
        _run("emps", 90.0, 120.0, 1.0),  # measured data: reported, not in the summary
    ]
    s = _summary(runs)
    assert s["max_cpu_s"] == 6.5
    assert s["max_wall_s"] == 75.0
    assert s["load_average_range"] == [1.0, 12.0]
    assert s["within_target_cpu"] is True
    assert s["within_target_wall"] is False  # 75 s > 60 s
    table = markdown(
        {"data": "SIMULATED", "runs": runs, "summary": s, "target_s": TARGET_S}
    ).splitlines()
    assert "| stribeck | 1 | 6.5 | 75.0 | 12.0 | stribeck | white |" in table
    assert "| clean | 1 | 4.0 | 20.0 | 3.0 | none | white |" in table


@pytest.mark.parametrize("other", ["--generalise", "--only-open"])
def test_time_with_another_bench_is_refused(
    tmp_path: Path, other: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "time.json"
    assert main(["bench", "calibrate", "--time", other, "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "--time" in err[0]
    assert not out.exists()
