"""`study bench master` end to end (quick), checked against closed-form references."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from study.bench.master import bandwidth_at
from study.cli import main
from teleop_core.master.params import DialParams
from tests.study.conftest import assert_figures


def test_bandwidth_interpolates_the_minus_2_db_crossing() -> None:
    freqs = np.array([1.0, 2.0, 3.0, 4.0])
    gain = np.array([0.0, -1.0, -3.0, -5.0])
    assert bandwidth_at(freqs, gain) == pytest.approx(2.5)
    assert math.isnan(bandwidth_at(freqs, np.zeros(4)))


def test_bench_master_quick_reproduces_the_dial_figures(tmp_path: Path) -> None:
    out_json = tmp_path / "master.json"
    argv = ["bench", "master", "--quick", "--json", str(out_json), "--out", str(tmp_path / "f")]
    assert main(argv) == 0
    report = json.loads(out_json.read_text())
    assert report["data"].startswith("SIMULATED")  # every figure and the JSON say so
    # the refitted polynomials stay within the JND of eqs. 14-15 over the calibrated range
    for branch in ("loading", "unloading"):
        assert report["calibration"][branch]["max_abs_difference_n"] < 0.192
    # two first-order lags (current loop, lever + gauge): |H|^2 = 10^-0.2 at the bandwidth
    p = DialParams()

    def gain_db(f: float) -> float:
        w = 2 * math.pi * f
        return -10 * math.log10(
            (1 + (w * p.current_time_constant_s) ** 2) * (1 + (w * p.gauge_time_constant_s) ** 2)
        )

    expected = brentq(lambda f: gain_db(f) - gain_db(1.0) + 2.0, 1.0, 50.0)
    assert report["frequency_response"]["bandwidth_minus_2db_hz"] == pytest.approx(
        expected, abs=0.5
    )
    rows = {r["link_delay_ms"]: r for r in report["latency"]["rows"]}
    assert rows[0.0]["latency_ms_max"] < 5.0
    assert rows[5.0]["increase_ms"] == pytest.approx(5.0, abs=1.0)
    assert report["closed_loop"]["realtime_factor_median"] > 1.0
    assert_figures(
        tmp_path / "f",
        "fig10b_calibration.png",
        "fig10c_frequency_response.png",
        "fig11_time_responses.png",
        "latency.png",
    )


def test_bench_master_with_a_missing_estimator_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["bench", "master", "--json", str(tmp_path / "m.json"), "--out", str(tmp_path)]
    assert main([*argv, "--estimator", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "nope" in err[0]
