"""Statistics against hand computation from the formulas (and pingouin where noted)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pingouin as pg
import pytest
from scipy import stats

from study.analysis.stats import compare_conditions, hedges_g_av, mixed_anova, mixed_model
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.exchange import TLX_COLUMNS, TLX_WEIGHT_COLUMNS, TRIAL_COLUMNS


def _long(values: dict[str, tuple[list[float], list[float]]], measure: str = "m") -> pd.DataFrame:
    rows = []
    for group, (vo, hv) in values.items():
        for i, (a, b) in enumerate(zip(vo, hv, strict=True)):
            code = f"{group[0].upper()}{i:02d}"
            rows += [
                {"participant": code, "group": group, "task": "lcca", "condition": "VO",
                 "measure": measure, "value": a},
                {"participant": code, "group": group, "task": "lcca", "condition": "HV",
                 "measure": measure, "value": b},
            ]  # fmt: skip
    return pd.DataFrame(rows)


VO = [10.0, 12.0, 9.0, 14.0, 11.0, 13.0]
HV = [9.0, 10.0, 9.0, 12.0, 10.0, 10.0]


def test_paired_t_and_hedges_g_av_by_hand() -> None:
    result, excluded = compare_conditions(_long({"novice": (VO, HV)}))
    row = result.iloc[0]
    assert row["test"] == "paired_t" and not excluded
    d = np.array(HV) - np.array(VO)  # -1, -2, 0, -2, -1, -3
    t = d.mean() / (d.std(ddof=1) / math.sqrt(6))  # -1.5 / (1.0488 / 2.4495) = -3.5032
    assert row["statistic"] == pytest.approx(t) and row["statistic"] == pytest.approx(
        -3.5032, abs=1e-4
    )
    assert row["p"] == pytest.approx(2 * stats.t.sf(abs(t), 5))
    # Lakens (2013): d_av = mean diff / mean SD; Hedges' J = 1 - 3 / (4 (n1 + n2) - 9)
    d_av = -1.5 / ((np.std(VO, ddof=1) + np.std(HV, ddof=1)) / 2)
    assert row["effect_size"] == pytest.approx(d_av * (1 - 3 / 39))
    # pingouin.compute_effsize(HV, VO, paired=True, eftype="hedges") standardises by the
    # root mean square of the SDs, sqrt((SD1^2 + SD2^2) / 2), not Lakens' d_av; the same
    # correction on that denominator reproduces it
    rms = math.sqrt((np.var(VO, ddof=1) + np.var(HV, ddof=1)) / 2)
    assert pg.compute_effsize(HV, VO, paired=True, eftype="hedges") == pytest.approx(
        -1.5 / rms * (1 - 3 / 39)
    )
    assert hedges_g_av(np.array(VO), np.array(HV)) == pytest.approx(d_av * (1 - 3 / 39))


def test_non_normal_differences_go_to_wilcoxon_with_exact_p() -> None:
    vo = [1.0] * 8
    hv = [1.1, 1.2, 1.15, 1.12, 1.18, 6.0, 1.11, 1.13]  # one huge difference: not normal
    row = compare_conditions(_long({"expert": (vo, hv)}))[0].iloc[0]
    assert row["shapiro_p"] < 0.05 and row["test"] == "wilcoxon"
    # every difference positive: W = min(R+, R-) = 0, exact two-sided p = 2 / 2^8
    assert row["statistic"] == 0.0
    assert row["p"] == pytest.approx(2 / 2**8)
    assert row["effect_size"] == pytest.approx(1.0)  # rank-biserial (R+ - R-) / sum = 1


def test_holm_across_groups_by_hand() -> None:
    result, _ = compare_conditions(
        _long(
            {
                "outsider": (VO, HV),
                "novice": (VO, [v - 0.5 + 0.1 * (i % 3) for i, v in enumerate(VO)]),
                "expert": (VO, [v + 0.2 * ((-1) ** i) for i, v in enumerate(VO)]),
            }
        )
    )
    p = result["p"].to_numpy()
    order = np.argsort(p)
    adjusted = np.empty(3)
    running = 0.0
    for rank, k in enumerate(order):  # p_(i) (m - i + 1), kept monotone
        running = max(running, min(1.0, p[k] * (3 - rank)))
        adjusted[k] = running
    assert np.allclose(result["p_holm"], adjusted)


def test_participants_missing_a_condition_are_excluded_and_said_so() -> None:
    long = _long({"novice": (VO, HV)})
    long = long[~((long["participant"] == "N02") & (long["condition"] == "HV"))]
    result, excluded = compare_conditions(long)
    assert result.iloc[0]["n"] == 5
    assert excluded == ["lcca/m/novice: excluded N02 (missing VO or HV)"]


def test_mixed_anova_condition_f_by_hand() -> None:
    groups = {
        "novice": ([10.0, 12.0, 9.0], [8.0, 11.0, 7.0]),
        "expert": ([7.0, 8.0, 6.0], [6.5, 7.0, 5.0]),
    }
    table = mixed_anova(_long(groups))[0].set_index("source")
    y = np.array([[vo[i], hv[i]] for vo, hv in groups.values() for i in range(3)])  # 6 x 2
    g = np.repeat([0, 1], 3)
    grand = y.mean()
    ss_cond = 6 * ((y.mean(axis=0) - grand) ** 2).sum()
    cell = np.array([[y[g == k, c].mean() for c in range(2)] for k in range(2)])
    resid = y - y.mean(axis=1, keepdims=True) - cell[g] + cell[g].mean(axis=1, keepdims=True)
    ss_err = (resid**2).sum()  # subject x condition within groups, df = (6 - 2)(2 - 1) = 4
    f = (ss_cond / 1) / (ss_err / 4)
    assert table.loc["condition", "F"] == pytest.approx(f)
    assert table.loc["condition", "df2"] == 4
    assert table.loc["condition", "np2"] == pytest.approx(ss_cond / (ss_cond + ss_err))


def test_mixed_model_condition_effect_is_the_mean_paired_difference() -> None:
    rows = []
    rng = np.random.default_rng(3)
    for group, shift in (("expert", -1.0), ("novice", -2.0)):
        for i in range(6):
            base = rng.normal(10, 2)
            for cond, effect in (("VO", 0.0), ("HV", shift)):
                for trial in range(3):
                    rows.append({"participant": f"{group}{i}", "group": group, "task": "lcca",
                                 "condition": cond, "m": base + effect + 0.1 * trial})  # fmt: skip
    trials = pd.DataFrame(rows)
    table, _ = mixed_model(trials, ("m",))
    est = table.set_index("term")["estimate"]
    # balanced design, reference group "expert": the HV coefficient is its mean difference
    assert est["C(condition, Treatment('VO'))[T.HV]"] == pytest.approx(-1.0, abs=1e-6)
    assert est["C(condition, Treatment('VO'))[T.HV]:C(group)[T.novice]"] == pytest.approx(
        -1.0, abs=1e-6
    )


def test_study_analyze_writes_the_json_contract(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = str(tmp_path / "s.db")
    (tmp_path / "d.toml").write_text(TEMPLATE)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    rng = np.random.default_rng(0)
    trials, tlx = [], []
    for k, group in enumerate(["novice"] * 5 + ["expert"] * 5):
        code = f"P{k + 1:03d}"
        for cond, shift in (("VO", 0.0), ("HV", -0.2)):
            for trial in (1, 2):
                proximal = 0.8 + shift + rng.normal(0, 0.05)
                time_s = 30 + rng.normal(0, 3)
                trials.append(
                    [code, group, "lcca", cond, trial, time_s, proximal, 0.4 + shift / 2, "true"]
                )
            if code != "P005":  # one questionnaire pair missing
                ratings = [int(v) for v in rng.integers(4, 16, 6) * 5]
                tlx.append([code, "lcca", cond, *ratings, 5, 0, 3, 2, 4, 1])
    pd.DataFrame(trials, columns=TRIAL_COLUMNS).to_csv(tmp_path / "t.csv", index=False)
    pd.DataFrame(tlx, columns=TLX_COLUMNS + TLX_WEIGHT_COLUMNS).to_csv(
        tmp_path / "x.csv", index=False
    )
    argv = ["import", "--trials", str(tmp_path / "t.csv"), "--tlx", str(tmp_path / "x.csv")]
    assert main([*argv, "--db", db]) == 0
    out = tmp_path / "analysis"
    assert main(["analyze", "--out", str(out), "--json", str(tmp_path / "a.json"), "--db", db]) == 0
    report = json.loads((tmp_path / "a.json").read_text())
    assert set(report) >= {"comparisons", "mixed_anova", "lmm", "exclusions"}
    first = report["comparisons"][0]
    assert list(first) == ["task", "measure", "group", "n", "mean_vo", "mean_hv", "sd_vo",
                           "sd_hv", "test", "statistic", "p", "p_holm", "effect_size",
                           "effect_size_kind"]  # fmt: skip
    measures = {c["measure"] for c in report["comparisons"]}
    assert {"completion_time_s", "peak_proximal_force_n", "tlx_raw", "tlx_weighted",
            "tlx_mental"} <= measures  # fmt: skip
    assert {a["source"] for a in report["mixed_anova"]} == {"group", "condition", "interaction"}
    assert set(report["lmm"][0]) == {"task", "measure", "term", "estimate", "se", "p"}
    tlx_novice = [c for c in report["comparisons"]
                  if c["measure"] == "tlx_raw" and c["group"] == "novice"]  # fmt: skip
    assert tlx_novice[0]["n"] == 4  # P005 has no questionnaires: not in the TLX analyses
    for name in ("comparisons.md", "comparisons.tex", "tests.csv"):
        assert (out / name).stat().st_size > 100
    # the exclusion (P005's questionnaires) is stated in every output
    assert any("P005" in e for e in report["exclusions"])
    assert "P005" in (out / "comparisons.md").read_text()
    assert "P005" in (out / "comparisons.tex").read_text()
    tests_csv = pd.read_csv(out / "tests.csv")
    assert tests_csv["note"].fillna("").str.contains("P005").any()
    capsys.readouterr()
    assert main(["analyze", "--out", str(out), "--task", "notes", "--db", db]) == 2
    assert "no data for task 'notes'" in capsys.readouterr().err
