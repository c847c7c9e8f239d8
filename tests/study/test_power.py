"""Power by simulation against the analytic paired t-test and the exact interaction test."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pingouin as pg
import pytest
from scipy import stats
from statsmodels.stats.power import TTestPower

from study.analysis.power import simulate_power
from study.cli import main


def test_no_effect_rejects_at_the_nominal_rate() -> None:
    result = simulate_power(
        {"a": 12, "b": 12}, {"a": 0.0, "b": 0.0}, 0.5, 1000, np.random.default_rng(1)
    )
    # binomial(1000, .05): sd = 0.0069; 4 sd either way
    for p in (*result.groups_uncorrected.values(), result.interaction):
        assert abs(p - 0.05) < 0.028
    # Holm across the two groups, as the analysis: each group's rate at most the
    # uncorrected one and at least that at alpha / 2 (Bonferroni's bound)
    for group, p in result.groups.items():
        assert p <= result.groups_uncorrected[group]
        assert abs(p - 0.0375) < 0.028  # between .025 and .05 at the null


def test_power_matches_the_analytic_paired_t_test() -> None:
    n, delta, rho = 10, 0.8, 0.5
    result = simulate_power({"g": n}, {"g": delta}, rho, 2000, np.random.default_rng(2))
    # d_z = delta / SD(diff), SD(diff) = sqrt(2 (1 - rho)); TTestPower().power(d_z, n, .05)
    d_z = delta / math.sqrt(2 * (1 - rho))
    analytic = TTestPower().power(effect_size=d_z, nobs=n, alpha=0.05)
    assert result.groups["g"] == pytest.approx(analytic, abs=0.04)  # 4 sd of 2000 draws


def test_the_interaction_is_the_one_way_anova_of_the_differences() -> None:
    rng = np.random.default_rng(3)
    rows, diffs = [], []
    for group, n, shift in (("a", 5, 0.0), ("b", 4, 1.0), ("c", 6, 0.5)):
        vo = rng.normal(0, 1, n)
        hv = vo + shift + rng.normal(0, 0.5, n)
        diffs.append(hv - vo)
        for i in range(n):
            rows += [(f"{group}{i}", group, "VO", vo[i]), (f"{group}{i}", group, "HV", hv[i])]
    data = pd.DataFrame(rows, columns=["participant", "group", "condition", "value"])
    # pg.mixed_anova(data, dv="value", within="condition", subject="participant", between="group")
    table = pg.mixed_anova(
        data=data, dv="value", within="condition", subject="participant", between="group"
    ).set_index("Source")
    one_way = stats.f_oneway(*diffs)
    assert table.loc["Interaction", "F"] == pytest.approx(one_way.statistic)


def test_power_command_writes_json_and_curve(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    design = tmp_path / "d.toml"
    design.write_text("[groups]\nnovice = 6\nexpert = 4\n")
    argv = ["power", "--design", str(design), "--effect", "novice=0.8,expert=0.4", "--n-sim", "40"]
    assert main([*argv, "--out", str(tmp_path / "p")]) == 0
    report = json.loads((tmp_path / "p" / "power.json").read_text())
    assert report["design"] == {"novice": 6, "expert": 4}
    assert set(report["groups"]) == {"novice", "expert"}
    assert 0 <= report["interaction"] <= 1
    assert [c["scale"] for c in report["curve"]] == [0.5, 0.75, 1.0, 1.5, 2.0, 3.0]
    assert (tmp_path / "p" / "power_curve.png").stat().st_size > 10_000
    # the caption beside the figure, naming the files it belongs to and the correction
    caption = (tmp_path / "p" / "captions.md").read_text()
    assert "## power_curve.pdf, power_curve.png" in caption
    assert "Holm's correction" in caption
    assert "\N{GREEK SMALL LETTER ALPHA} = .05" in caption
    capsys.readouterr()
    assert main(["power", "--design", str(design), "--effect", "novice=0.8"]) == 2
    assert "lacks expert" in capsys.readouterr().err
