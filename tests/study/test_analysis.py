"""Statistics against hand computation from the formulas (and pingouin where noted)."""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pingouin as pg
import pytest
from scipy import stats

from study.analysis.comparisons import compare_conditions, holm
from study.analysis.mixed_model import mixed_model
from study.analysis.paired import hedges_g_av
from study.analysis.signed_rank import signed_rank
from study.analysis.stats import mixed_anova
from study.cli import main
from study.protocol.exchange import TLX_COLUMNS, TLX_WEIGHT_COLUMNS, TRIAL_COLUMNS
from tests.study.conftest import init_study, modules_loaded


def report_keys_added() -> list[str]:
    """The comparison keys added after the first eleven (`report.COMPARISON_KEYS`)."""
    from study.analysis.report import COMPARISON_KEYS

    return list(COMPARISON_KEYS[15:])


def _long(values: dict[str, tuple[list[float], list[float]]], measure: str = "m") -> pd.DataFrame:
    rows = []
    for group, (vo, hv) in values.items():
        for i, (a, b) in enumerate(zip(vo, hv, strict=True)):
            code = f"{group[0].upper()}{i:02d}"
            rows += [
                {
                    "participant": code,
                    "group": group,
                    "task": "lcca",
                    "condition": "VO",
                    "measure": measure,
                    "value": a,
                },
                {
                    "participant": code,
                    "group": group,
                    "task": "lcca",
                    "condition": "HV",
                    "measure": measure,
                    "value": b,
                },
            ]
    return pd.DataFrame(rows)


VO = [10.0, 12.0, 9.0, 14.0, 11.0, 13.0]
HV = [9.0, 10.0, 9.0, 12.0, 10.0, 10.0]


def test_paired_t_and_hedges_g_av_by_hand() -> None:
    result, excluded = compare_conditions(_long({"novice": (VO, HV)}))
    row = result.iloc[0]
    assert row["test"] == "paired_t"
    assert not excluded
    d = np.array(HV) - np.array(VO)  # -1, -2, 0, -2, -1, -3
    t = d.mean() / (d.std(ddof=1) / math.sqrt(6))  # -1.5 / (1.0488 / 2.4495) = -3.5032
    assert row["statistic"] == pytest.approx(t)
    assert row["statistic"] == pytest.approx(-3.5032, abs=1e-4)
    assert row["p"] == pytest.approx(2 * stats.t.sf(abs(t), 5))
    # Lakens (2013): d_av = mean diff / mean SD; Hedges' J = 1 - 3 / (4 (n1 + n2) - 9)
    d_av = -1.5 / ((np.std(VO, ddof=1) + np.std(HV, ddof=1)) / 2)
    assert row["effect_size"] == pytest.approx(d_av * (1 - 3 / 19))
    # pingouin.compute_effsize(HV, VO, paired=True, eftype="hedges") standardises by the
    # root mean square of the SDs, sqrt((SD1^2 + SD2^2) / 2), not Lakens' d_av; the same
    # correction on that denominator reproduces it
    rms = math.sqrt((np.var(VO, ddof=1) + np.var(HV, ddof=1)) / 2)
    assert pg.compute_effsize(HV, VO, paired=True, eftype="hedges") == pytest.approx(
        -1.5 / rms * (1 - 3 / 39)
    )
    assert hedges_g_av(np.array(VO), np.array(HV)) == pytest.approx(d_av * (1 - 3 / 19))


def test_non_normal_differences_go_to_wilcoxon_with_exact_p() -> None:
    vo = [1.0] * 8
    hv = [1.1, 1.2, 1.15, 1.12, 1.18, 6.0, 1.11, 1.13]  # one huge difference: not normal
    row = compare_conditions(_long({"expert": (vo, hv)}))[0].iloc[0]
    assert row["shapiro_p"] < 0.05
    assert row["test"] == "wilcoxon"
    # every difference positive: V = R+ = 1 + ... + 8 = 36 (R's statistic), exact
    # two-sided p = 2 / 2^8
    assert row["statistic"] == 36.0
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


@pytest.mark.parametrize(
    "p",
    [
        [0.01, 0.04, 0.03, 0.2],
        [0.03, float("nan"), 0.03, 0.5, 0.001],  # a tie and a test that could not run
        [float("nan"), float("nan")],
        [0.9, 0.8],  # clipped at 1
        [],
    ],
)
def test_holm_equals_pingouin(p: list[float]) -> None:
    # the reference: pingouin.multicomp(p, method="holm"), which the analysis used before
    expected = pg.multicomp(np.array(p, dtype=float), method="holm")[1]
    assert np.array_equal(holm(np.array(p, dtype=float)), expected, equal_nan=True)


def test_study_analyze_imports_neither_pingouin_nor_plotting() -> None:
    # a fresh process: pingouin pulls in seaborn, matplotlib and xarray (seconds of imports)
    code = "import study.commands.analyze, study.analysis.report, study.analysis.frames"
    heavy = ("pingouin", "matplotlib", "seaborn", "statsmodels.formula.api")
    assert modules_loaded(code, heavy) == []


def test_participants_missing_a_condition_are_excluded_and_said_so() -> None:
    long = _long({"novice": (VO, HV)})
    long = long[~((long["participant"] == "N02") & (long["condition"] == "HV"))]
    result, excluded = compare_conditions(long)
    assert result.iloc[0]["n"] == 5
    assert excluded == ["lcca/m/novice: excluded N02 (one condition missing: no HV)"]


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
                    rows.append(
                        {
                            "participant": f"{group}{i}",
                            "group": group,
                            "task": "lcca",
                            "condition": cond,
                            "m": base + effect + 0.1 * trial,
                        }
                    )
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
    db = init_study(tmp_path)
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
    argv = [
        "import",
        "--enrol-new",
        "--trials",
        str(tmp_path / "t.csv"),
        "--tlx",
        str(tmp_path / "x.csv"),
    ]
    assert main([*argv, "--db", db]) == 0
    out = tmp_path / "analysis"
    assert main(["analyze", "--out", str(out), "--json", str(tmp_path / "a.json"), "--db", db]) == 0
    report = json.loads((tmp_path / "a.json").read_text())
    assert set(report) >= {"comparisons", "mixed_anova", "lmm", "exclusions"}
    first = report["comparisons"][0]
    assert list(first) == [
        "task",
        "measure",
        "group",
        "n",
        "mean_vo",
        "mean_hv",
        "sd_vo",
        "sd_hv",
        "test",
        "statistic",
        "p",
        "p_holm",
        "effect_size",
        "effect_size_kind",
        "p_method",
        *report_keys_added(),
    ]
    measures = {c["measure"] for c in report["comparisons"]}
    assert {
        "completion_time_s",
        "peak_proximal_force_n",
        "tlx_raw",
        "tlx_weighted",
        "tlx_mental",
    } <= measures
    assert {a["source"] for a in report["mixed_anova"]} == {"group", "condition", "interaction"}
    assert set(report["lmm"][0]) >= {"task", "measure", "term", "estimate", "se", "p", "p_method"}
    assert set(report["lmm"][0]) - {
        "task",
        "measure",
        "term",
        "estimate",
        "se",
        "p",
        "p_method",
    } == {"kind", "df", "t", "ci_low", "ci_high", "reference"}
    assert {r["p_method"] for r in report["lmm"]} == {"Satterthwaite t"}
    assert report["methods"]["mixed_anova"]["ss_type"] == 2  # the default, stated
    assert {a["ss_type"] for a in report["mixed_anova"]} == {2}
    tlx_novice = [
        c for c in report["comparisons"] if c["measure"] == "tlx_raw" and c["group"] == "novice"
    ]
    assert tlx_novice[0]["n"] == 4  # P005 has no questionnaires: not in the TLX analyses
    for name in ("comparisons.md", "comparisons.tex", "tests.csv", "methods.md"):
        assert (out / name).stat().st_size > 100
    for table in ("descriptives", "comparisons", "mixed_anova", "lmm"):
        tex = (out / f"{table}.tex").read_text()
        assert "\\toprule" in tex
        assert "\\bottomrule" in tex
        assert "\\caption{" in tex
        assert (out / f"{table}.md").read_text().startswith(f"**Table: {table}.**")
        assert len(pd.read_csv(out / f"{table}.csv")) > 0
    methods = (out / "methods.md").read_text()
    for phrase in (
        "Type II sums of squares (the default)",
        "Holm",
        "Satterthwaite",
        "REML",
        "Shapiro-Wilk",
        "its p is exact",
        "numpy ",
        "(\N{GREEK SMALL LETTER ALPHA} = .05)",
    ):
        assert phrase in methods
    # what a paper can take: APA numbers, nothing of the implementation (the software
    # versions, on their own last line, aside)
    body = methods.split("\nSoftware:")[0]
    for word in ("alpha", "0.05", "1e-", "sqrt(", "scipy", "pingouin", "statsmodels",
                 "lme4's", "isSingular", "+/-"):  # fmt: skip
        assert word not in body, word
    assert re.findall(r"\bp(?:\(Holm\))? = \.\d{4,}", body) == []  # at most 3 decimals
    assert re.findall(r"\bp(?:\(Holm\))? = 0\.", body) == []  # no leading zero
    assert "Type II sums of squares (the default)" in (out / "mixed_anova.tex").read_text()
    assert "p (Satterthwaite)" in (out / "lmm.md").read_text()
    assert "reference levels: condition VO, group expert" in (out / "lmm.md").read_text()
    # the exclusion (P005's questionnaires) is stated in every output
    assert any("P005" in e for e in report["exclusions"])
    assert "P005" in (out / "comparisons.md").read_text()
    assert "P005" in (out / "comparisons.tex").read_text()
    tests_csv = pd.read_csv(out / "tests.csv")
    assert tests_csv["note"].fillna("").str.contains("P005").any()
    capsys.readouterr()
    assert main(["analyze", "--out", str(out), "--task", "notes", "--db", db]) == 2
    assert "no data for task 'notes'" in capsys.readouterr().err
    out3 = tmp_path / "type3"
    assert main(["analyze", "--out", str(out3), "--ss-type", "3", "--db", db]) == 0
    report3 = json.loads((out3 / "analysis.json").read_text())
    assert {a["ss_type"] for a in report3["mixed_anova"]} == {3}
    assert "Type III sums of squares," in (out3 / "methods.md").read_text()
    assert main(["analyze", "--out", str(out3), "--ss-type", "1", "--db", db]) == 2


DEMO_MEANS = Path(__file__).parent.parent / "data" / "demo_seed1_means.csv"
"""Participant means of `study demo --seed 1` (36 participants: 20 outsiders, 8 novices,
8 experts; four measures), written by `participant_means` on the demo database."""

# R 4.2.2, afex 1.2.1, on tests/data/demo_seed1_means.csv:
#   d <- read.csv("demo_seed1_means.csv"); s <- d[d$measure == m, ]
#   aov_ez("participant", "value", s, between = "group", within = "condition",
#          type = ty, anova_table = list(es = "pes", correction = "none"))
# columns: F, Pr(>F), pes for group, condition, group:condition (printed to 12 digits)
AFEX = {
    ("completion_time_s", 2): [
        (7.231398183085, 0.00248685346378, 0.304718589579),
        (10.515660560822, 0.00270840837380, 0.241652325285),
        (0.586604591339, 0.56190757305701, 0.034331255704),
    ],
    ("completion_time_s", 3): [
        (7.231398183085, 0.00248685346378, 0.304718589579),
        (9.352709648518, 0.00439463346009, 0.220829073892),
        (0.586604591339, 0.56190757305701, 0.034331255704),
    ],
    ("peak_proximal_force_n", 2): [
        (8.62982649650, 9.66848644552e-04, 0.343409712666),
        (62.18117468232, 4.31381047181e-09, 0.653292784943),
        (8.06629639128, 1.40565984701e-03, 0.328348085638),
    ],
    ("peak_proximal_force_n", 3): [
        (8.62982649650, 9.66848644552e-04, 0.343409712666),
        (31.20052626357, 3.27245769090e-06, 0.485985521917),
        (8.06629639128, 1.40565984701e-03, 0.328348085638),
    ],
    ("peak_distal_force_n", 2): [
        (10.47839736752, 2.99722020478e-04, 0.388399548897),
        (62.22883097912, 4.27780649359e-09, 0.653466291031),
        (8.46827963717, 1.07540699069e-03, 0.339161518544),
    ],
    ("peak_distal_force_n", 3): [
        (10.47839736752, 2.99722020478e-04, 0.388399548897),
        (30.98900515267, 3.46101863991e-06, 0.484286403246),
        (8.46827963717, 1.07540699069e-03, 0.339161518544),
    ],
    ("tlx_raw", 2): [
        (3.53683391095, 4.05793380547e-02, 0.176516605701),
        (26.52060292459, 1.18599402508e-05, 0.445570132382),
        (2.34088410618, 1.12024751717e-01, 0.124244918284),
    ],
    ("tlx_raw", 3): [
        (3.53683391095, 0.040579338054718, 0.176516605701),
        (14.65882210787, 0.000545671878993, 0.307578355056),
        (2.34088410618, 0.112024751716547, 0.124244918284),
    ],
}


@pytest.mark.parametrize("ss_type", [2, 3])
def test_mixed_anova_equals_afex_on_the_demo_study(ss_type: int) -> None:
    long = pd.read_csv(DEMO_MEANS)
    table, notes = mixed_anova(long, ss_type=ss_type)
    assert any("unequal group sizes outsider 20, novice 8, expert 8" in n for n in notes)
    for measure in ("completion_time_s", "peak_proximal_force_n", "peak_distal_force_n", "tlx_raw"):
        rows = table[table["measure"] == measure].set_index("source")
        for source, (f, p, pes) in zip(
            ("group", "condition", "interaction"), AFEX[(measure, ss_type)], strict=True
        ):
            assert rows.loc[source, "F"] == pytest.approx(f, abs=1e-6), (measure, source)
            assert rows.loc[source, "p"] == pytest.approx(p, abs=1e-6), (measure, source)
            assert rows.loc[source, "np2"] == pytest.approx(pes, abs=1e-6), (measure, source)
            assert rows.loc[source, "df2"] == 33  # 36 participants - 3 groups
    if ss_type == 2:  # Type II is also pingouin's mixed ANOVA
        g = long[long["measure"] == "peak_proximal_force_n"]
        pg_table = pg.mixed_anova(
            data=g, dv="value", within="condition", subject="participant", between="group"
        )
        assert table.loc[table["measure"] == "peak_proximal_force_n", "F"].tolist() == (
            pytest.approx(pg_table["F"].tolist(), rel=1e-9)
        )


def test_mixed_anova_refuses_an_unknown_ss_type() -> None:
    with pytest.raises(ValueError, match="sums-of-squares type 1; expected 2 or 3"):
        mixed_anova(pd.read_csv(DEMO_MEANS), ss_type=1)


# R, coin 1.4: the exact conditional p (zeros ranked, Pratt: coin's default)
#   df <- data.frame(y = d, x = 0)
#   pvalue(wilcoxsign_test(y ~ x, data = df, distribution = "exact"))
#   d1 four zeros -> 0.125     (wilcox.test's normal approximation: 0.100348246462291)
#   d2 a tie      -> 0.0390625 (wilcox.test: 0.0420627333567661)
#   d3 distinct   -> 0.0546875 (wilcox.test's exact p, the same)
#   V: r <- rank(abs(d)); sum(r[d > 0]) -> d1 26, d2 33, d3 32
@pytest.mark.parametrize(
    ("diff", "p", "v"),
    [
        ([0, 0, 0, 0, 0.05, 0.12, 0.03, 0.2], 0.125, 26.0),
        ([0.1, 0.1, 0.3, -0.2, 0.5, 0.6, 0.7, 0.9], 0.0390625, 33.0),
        ([0.11, 0.32, -0.25, 0.54, 0.61, 0.73, 0.95, -0.05], 0.0546875, 32.0),
    ],
)
def test_signed_rank_is_coin_exact(diff: list[float], p: float, v: float) -> None:
    got = signed_rank(np.array(diff))
    assert (got.v, got.method) == (v, "exact")
    assert got.p == pytest.approx(p, abs=1e-12)


def test_a_residual_of_exactly_zero_gives_no_f_and_a_note() -> None:
    """HV = VO + a constant per group (a coarse rating scale does this): the differences
    have no within-group variance, so there is no error to test the condition and the
    interaction against. The ratio of rounding errors gave F ~ 1e31 and p < .001; now
    neither has an F or a p (null in analysis.json), the note says why, and the group
    term (the participants' means do vary) keeps its F."""
    import json
    import math

    from study.analysis.report import ANOVA_KEYS, _records

    rows = []
    for group, shift in (("novice", 0.1), ("expert", 0.3)):
        for i in range(4):
            # 0.1 and 0.3 are not exact in binary: the differences carry rounding noise
            for condition, value in (("VO", 10.0 + i * 0.7), ("HV", 10.0 + i * 0.7 + shift)):
                rows.append(
                    {
                        "participant": f"{group}{i}",
                        "group": group,
                        "task": "lcca",
                        "measure": "m",
                        "condition": condition,
                        "value": value,
                    }
                )
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        table, notes = mixed_anova(pd.DataFrame(rows))
    rows_by = table.set_index("source")
    for source in ("condition", "interaction"):
        assert math.isnan(rows_by.loc[source, "F"]), source
        assert math.isnan(rows_by.loc[source, "p"]), source
        assert math.isnan(rows_by.loc[source, "np2"]), source
    # the group term: one-way ANOVA of the participant sums, as scipy's f_oneway gives it
    from scipy.stats import f_oneway

    by_group: dict[str, list[float]] = {}
    for r in rows:
        by_group.setdefault(r["group"], []).append(r["value"])
    one_way = f_oneway(*[np.add(v[0::2], v[1::2]) for v in by_group.values()])
    assert rows_by.loc["group", "F"] == pytest.approx(one_way.statistic, rel=1e-10)
    assert rows_by.loc["group", "p"] == pytest.approx(one_way.pvalue, rel=1e-10)
    assert notes == [
        "lcca/m: mixed ANOVA condition and interaction not testable (the HV - VO "
        "differences do not vary within groups)"
    ]
    records = _records(table.to_dict("records"), ANOVA_KEYS)
    json.dumps(records, allow_nan=False)  # strict JSON
    assert [r["F"] is None for r in records] == [False, True, True]


def test_identical_answers_give_an_undefined_f_without_a_warning() -> None:
    """Every participant gives the same value in both conditions (identical TLX answers):
    effect and error sums of squares are both zero, so F, p and partial eta squared are
    0 / 0, undefined (nan, null in the JSON), and no RuntimeWarning reaches the user."""
    rows = [
        {
            "participant": f"{group}{i}",
            "group": group,
            "task": "lcca",
            "measure": "m",
            "condition": condition,
            "value": 50.0,
        }
        for group in ("novice", "expert")
        for i in range(3)
        for condition in ("VO", "HV")
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        table, _ = mixed_anova(pd.DataFrame(rows))
    assert table[["F", "p", "np2"]].isna().all().all()


# A study on a 0.01 s grid whose HV - VO differences hold a tie (1.20 twice, computed as
# 1.1999999999999993 and 1.1999999999999957), a near tie at the resolution (0.80, 0.81)
# and a noise zero (10.1 + 0.2 - 10.3 = -1.8e-15). R 4.2.2 on the differences at their
# resolution (coin 1.4, the exact conditional p; wilcox.test for what it gave before):
#   d <- round(hv - vo, 2); df <- data.frame(y = d, x = 0)
#   pvalue(wilcoxsign_test(y ~ x, data = df, distribution = "exact"))  # 0.0283203125
#   r <- rank(abs(d)); sum(r[d > 0]); sum(r[d < 0])  # 76, 14 (the zero ranked 1)
#   vo <- c(20.00, 30.85, 25.13, 27.40, 22.75, 33.10, 29.95, 24.60, 31.20, 26.05, 28.33,
#           23.47, 10.3)
#   hv <- c(21.2, 32.05, 24.78, 29.5, 23.55, 31.55, 33.35, 25.41, 44.1, 27.8, 27.73,
#           24.42, 10.3)
#   wilcox.test(round(hv - vo, 2))  # V = 67, p-value = 0.0309194601975077, with the
#                                   # warnings "cannot compute exact p-value with ties"
#                                   # and "... with zeroes"
#   wilcox.test(hv[1:12] - vo[1:12])  # unrounded: V = 67, exact p = 0.02685546875, the
#                                     # floating-point noise deciding the method
TIED_VO = [20.00, 30.85, 25.13, 27.40, 22.75, 33.10, 29.95, 24.60, 31.20, 26.05, 28.33, 23.47, 10.3]
TIED_HV = [
    21.2,
    32.05,
    24.78,
    29.5,
    23.55,
    31.55,
    33.35,
    25.41,
    44.1,
    27.8,
    27.73,
    24.42,
    10.1 + 0.2,
]


def test_wilcoxon_ties_and_zeros_at_the_data_resolution_equal_r() -> None:
    from study.analysis.paired import at_resolution

    vo, hv = np.array(TIED_VO), np.array(TIED_HV)
    assert len(set(np.abs(hv - vo))) == 13  # the raw floats: no tie, no zero
    got = signed_rank(at_resolution(hv - vo, 44.1))
    assert (got.v, got.method, got.n_zero) == (76.0, "exact", 1)
    assert got.p == pytest.approx(0.0283203125, abs=1e-12)
    # through the analysis: non-normal differences (the 12.9 s outlier) go to Wilcoxon
    result, _ = compare_conditions(_long({"novice": (list(vo), list(hv))}))
    row = result.iloc[0]
    assert (row["test"], row["statistic"], row["p_method"]) == ("wilcoxon", 76.0, "exact")
    assert row["p"] == pytest.approx(0.0283203125, abs=1e-12)
    # rank-biserial on the same ranks: (R+ - R-) / (R+ + R-) = (76 - 14) / 90
    assert row["effect_size"] == pytest.approx((76 - 14) / 90, abs=1e-12)


def test_near_ties_stay_distinct() -> None:
    from study.analysis.paired import at_resolution

    d = at_resolution(np.array([0.8000000000000007, 0.8099999999999987, 1.2]), 40.0)
    assert len(set(d)) == 3  # 0.80 and 0.81 differ by far more than the resolution


DEMO_TRIALS = Path(__file__).parent.parent / "data" / "demo_seed1_trials.csv"
"""`study export` of `study demo --seed 1` (216 LCCA trials of 36 simulated participants)."""

# R 4.2.2, lme4 1.1-31, at the REML optimum: lme4's own optimiser stops within about 1e-8
# of it (SEs differ from the values below by up to 1.3e-8 relative), so theta is polished
# on lme4's deviance function and the model evaluated there:
#   d <- read.csv("demo_seed1_trials.csv"); d$condition <- relevel(factor(d$condition), "VO")
#   d$value <- d[[m]]
#   f0 <- lmer(value ~ condition * group + (1 | participant), d, REML = TRUE)
#   dev <- lmer(..., devFunOnly = TRUE); t0 <- getME(f0, "theta")
#   h <- seq(-0.01, 0.01, length.out = 41) * t0; y <- sapply(t0 + h, dev)
#   cf <- coef(lm(y ~ h + I(h^2) + I(h^3)))   # theta = t0 + the root of the cubic's slope
#   f <- lmer(..., start = list(theta = th), control = lmerControl(optimizer = NULL))
#   fixef(f); sqrt(diag(vcov(f))); isSingular(f0)  # FALSE for all three measures
# rows: (estimate, SE) of Intercept, HV, novice, outsider, HV:novice, HV:outsider
LME4 = {
    "completion_time_s": (
        0.72731518581495413,
        [
            (23.5566666666669953, 3.1935777713747311),
            (3.0149999999999659, 2.8080022939928941),
            (9.1899999999996371, 4.5164009967713801),
            (11.9633333333331819, 3.7786921777972711),
            (2.8283333333333864, 3.9711149273395145),
            (1.2249999999999819, 3.3224731204777402),
        ],
    ),
    "peak_proximal_force_n": (
        0.23179884414988436,
        [
            (0.654986757299080513, 0.063749683056112103),
            (-0.088459671184823022, 0.083664455544403257),
            (0.078670136328576820, 0.090155666374940019),
            (0.374747173674815748, 0.075429642221454582),
            (-0.080931714866508381, 0.118319407719455968),
            (-0.337929661949778692, 0.098993118802056135),
        ],
    ),
    "peak_distal_force_n": (
        0.13531450527827771,
        [
            (0.216786258852353780, 0.055185227528665379),
            (-0.061372116258316345, 0.075984673972566960),
            (0.097012265457953495, 0.078043697213683663),
            (0.340877044003124352, 0.065296041781617908),
            (-0.084457702070322438, 0.107458556464502128),
            (-0.286398036040933057, 0.089906278702903769),
        ],
    ),
}


def test_mixed_model_equals_lme4_reml_on_the_demo_study() -> None:
    from study.analysis.mixed_model import lmm_design
    from study.analysis.stats_lmm import fit_random_intercept

    trials = pd.read_csv(DEMO_TRIALS)
    table, notes = mixed_model(trials)
    assert notes == []  # lme4's isSingular is FALSE: no boundary warning
    for measure, (theta, rows) in LME4.items():
        got = table[(table["measure"] == measure) & (table["kind"] == "coefficient")]
        assert len(got) == 6
        for (est, se), (_, row) in zip(rows, got.iterrows(), strict=True):
            assert row["estimate"] == pytest.approx(est, rel=1e-8, abs=1e-12), measure
            assert row["se"] == pytest.approx(se, rel=1e-8), measure
        data = trials.rename(columns={measure: "value"})
        fit = fit_random_intercept(
            lmm_design(data)[0], data["value"].to_numpy(float), data["participant"].to_numpy()
        )
        assert fit.theta == pytest.approx(theta, rel=1e-8)


# R 4.2.2, lme4 1.1-31, on the trials built below (each participant of a group has the
# same values in another order, so no participant variance):
#   f <- lmer(value ~ condition * group + (1 | participant), d)
#   -> "boundary (singular) fit"; isSingular(f) TRUE; theta 0
#   fixef: 11.1666666666667, -2.33333333333333, 2, 0
#   SE:    0.300462606288666, 0.424918292799399, 0.424918292799399, 0.600925212577332
def test_a_singular_fit_is_noted_and_equals_lme4() -> None:
    base = [10, 11, 12.5, 9, 9.5, 8]
    rows = []
    for i in range(6):
        group = "expert" if i < 3 else "novice"
        k = i % 3
        order = [k, (k + 1) % 3, (k + 2) % 3]
        values = [base[j] for j in order] + [base[3 + j] for j in order]
        for v, cond in zip(values, ["VO"] * 3 + ["HV"] * 3, strict=True):
            rows.append(
                {
                    "participant": f"P{i + 1:02d}",
                    "group": group,
                    "task": "lcca",
                    "condition": cond,
                    "m": v + 2 * (group == "novice"),
                }
            )
    table, notes = mixed_model(pd.DataFrame(rows), ("m",))
    assert len(notes) == 1
    assert "singular fit" in notes[0]
    assert "isSingular" in notes[0]
    ref = [
        (11.1666666666667, 0.300462606288666),
        (-2.33333333333333, 0.424918292799399),
        (2.0, 0.424918292799399),
        (0.0, 0.600925212577332),
    ]
    table = table[table["kind"] == "coefficient"]
    for (est, se), (_, row) in zip(ref, table.iterrows(), strict=True):
        assert row["estimate"] == pytest.approx(est, rel=1e-12, abs=1e-12)
        assert row["se"] == pytest.approx(se, rel=1e-12)


def test_apa_text() -> None:
    from study.analysis.apa import bounded_text, p_text
    from study.analysis.figcheck import stars

    assert p_text(1.0) == "> .999"
    assert p_text(0.9995) == "> .999"
    assert p_text(0.0456) == ".046"
    assert p_text(0.00099) == "< .001"
    # never rounded across a star threshold: the text and the figure's mark agree
    for p in (0.04996, 0.0500001, 0.0099996, 0.010004, 0.0010004, 0.049, 0.051):
        text = p_text(p)
        shown = float(text.lstrip("< ")) - (1e-9 if text.startswith("<") else 0.0)
        assert stars(shown) == stars(p), p
        assert len(text.split(".")[1]) <= 3, text
    # three decimals at most: where they would cross a threshold, the threshold is the bound
    assert p_text(0.04996) == "< .05"
    assert p_text(0.0099996) == "< .01"
    assert p_text(0.0500001) == ".050"
    assert bounded_text(0.6532) == ".65"
    assert bounded_text(-0.25) == "-.25"
    assert bounded_text(0.6532, 3) == ".653"
    assert bounded_text(float("nan")) == "n/a"


def test_tables_give_t_df_v_and_human_labels() -> None:
    from study.analysis.stats import analyze
    from study.analysis.tables import anova_table, comparisons_table, lmm_table

    normal = _long({"novice": (VO, HV), "expert": (list(TIED_VO), list(TIED_HV))})
    trials = normal.rename(columns={"value": "completion_time_s"})
    trials = trials[trials["measure"] == "m"].drop(columns="measure")
    trials = trials.assign(
        peak_proximal_force_n=trials["completion_time_s"] / 10,
        peak_distal_force_n=trials["completion_time_s"] / 20,
    )
    analysis = analyze(trials, normal)
    c = comparisons_table(analysis).display.set_index("group")
    assert c.loc["novice", "statistic"].startswith("t(5) = ")  # 6 pairs, df 5
    assert c.loc["expert", "statistic"] == "V = 76.0"  # Pratt ranks: the zero ranked 1
    assert c.loc["expert", "effect size"] == "rank-biserial r = .69"  # (76 - 14) / 90, Pratt ranks
    assert c.loc["novice", "effect size"].startswith("Hedges' g_av = -")
    assert c.loc["expert", "test"] == "Wilcoxon signed-rank"
    anova = anova_table(analysis).display
    assert all(v.startswith(".") or v in ("1.000", "n/a") for v in anova["partial eta squared"])
    terms = lmm_table(analysis).display["term"].tolist()
    assert terms[:4] == ["intercept", "HV (in expert)", "novice", "HV x novice"]
    assert terms[4:6] == ["VO (mean over groups)", "HV (mean over groups)"]
    assert terms[6] == "HV - VO (mean over groups)"


def test_a_mixed_model_without_residual_df_is_a_note_not_an_error() -> None:
    rows = [
        {"participant": f"P{i}", "group": g, "task": "lcca", "condition": c, "m": v}
        for i, (g, c, v) in enumerate(
            [("a", "VO", 1.0), ("a", "HV", 2.0), ("b", "VO", 3.0), ("b", "HV", 5.0)]
        )
    ]
    table, notes = mixed_model(pd.DataFrame(rows), ("m",))
    assert table.empty
    assert notes == [
        "lcca/m: mixed model could not be fitted: 4 trials for 4 fixed effects: no residual "
        "degrees of freedom"
    ]


# R 4.2.2 on tests/data/demo_seed1_means.csv, per measure m and group g:
#   w <- reshape(s[, c("participant", "condition", "value")], idvar = "participant",
#                timevar = "condition", direction = "wide"); d <- w$value.HV - w$value.VO
#   t.test(w$value.HV, w$value.VO, paired = TRUE)   # t, p
#   x <- round(d, 9)                                 # d at the data's resolution
#   pvalue(wilcoxsign_test(y ~ z, data = data.frame(y = x, z = 0),
#                          distribution = "exact"))  # coin 1.4: the exact conditional p
#   r <- rank(abs(x)); sum(r[x > 0])                 # V
#   shapiro.test(d)$p.value
# (t, p_t, V, p_W, shapiro p); the outsiders' completion time holds a tie that floating-
# point noise had split (then "exact" p = .189; wilcox.test on the tie: asymptotic .191;
# coin's exact conditional p on the tie: .1925)
R_DEMO = {
    ("completion_time_s", "outsider"): (
        1.98398848224652,
        0.0618942430020153,
        140.5,
        0.192543029785156,
        0.0151792852311702,
    ),
    ("completion_time_s", "novice"): (
        2.35162813545057,
        0.0509652280723797,
        32,
        0.0546875,
        0.932873233060212,
    ),
    ("peak_proximal_force_n", "outsider"): (
        -7.21836971644834,
        7.45093920504869e-07,
        0,
        1.9073486328125e-06,
        0.0430613214458504,
    ),
    ("peak_proximal_force_n", "expert"): (
        -1.62522394325726,
        0.148142318187824,
        5,
        0.078125,
        0.00134195845507016,
    ),
    ("peak_distal_force_n", "expert"): (
        -1.28628418260779,
        0.239250924916312,
        6,  # four zeros ranked 1-4 (Pratt); wilcox.test drops them: V = 2, p = .361
        0.375,
        0.00635893776220218,
    ),
    ("tlx_raw", "outsider"): (
        -5.17021276595745,
        5.44354877219215e-05,
        11,
        0.000479738755364896,
        0.599337802674218,
    ),
}


def test_comparisons_equal_r_on_the_demo_study() -> None:
    table, _ = compare_conditions(pd.read_csv(DEMO_MEANS))
    rows = table.set_index(["measure", "group"])
    for key, (t, p_t, v, p_w, shapiro_p) in R_DEMO.items():
        row = rows.loc[key]
        assert row["shapiro_p"] == pytest.approx(shapiro_p, rel=1e-8), key
        if row["test"] == "paired_t":
            assert row["statistic"] == pytest.approx(t, rel=1e-8), key
            assert row["p"] == pytest.approx(p_t, rel=1e-8), key
        else:
            assert row["statistic"] == v, key
            assert row["p"] == pytest.approx(p_w, rel=1e-8), key
    outsider = rows.loc[("completion_time_s", "outsider")]
    assert (outsider["test"], outsider["p_method"]) == ("wilcoxon", "exact")


def test_latex_and_csv_are_pandas_layout() -> None:
    """The tables' own LaTeX and CSV writers against pandas' Styler.to_latex and to_csv,
    which wrote them before (text to escape, an int column with a gap, NaN, inf)."""
    import io

    from study.analysis.tables import Table, _csv_cell, _csv_formatters

    header = ("task", "95 % CI", "n", "p_x")
    cells = [
        ["lcca", "a_b & {c} ~ d^e \\f $#", 20, "< .001"],
        ["notes", "[1.000, 2.000]", 8, ".046"],
    ]
    table = Table("t", header, [], header, cells, "A caption_with 50 % & more.")
    styler = (
        pd.DataFrame(cells, columns=list(header))
        .style.hide(axis="index")
        .format(escape="latex")
        .format_index(escape="latex", axis=1)
    )
    expected = styler.to_latex(
        hrules=True,
        caption="A caption\\_with 50 \\% \\& more.",
        label="tab:t",
        position_float="centering",
    ).replace("< .001", "$<$ .001")
    assert table.latex() == expected
    rows = [
        {"a": "x,y", "n": 20, "f": 0.1, "b": True, "s": "=1+1"},
        {"a": "z", "f": float("nan")},
        {"a": None, "n": 3, "f": float("inf"), "s": "-0.5"},
    ]
    columns = ["a", "n", "f", "b", "s"]
    buffer = io.StringIO()
    writer = __import__("csv").writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    floats = _csv_formatters(columns, rows)
    for r in rows:
        writer.writerow([_csv_cell(r.get(c), f) for c, f in zip(columns, floats, strict=True)])
    from study.protocol.export_files import escape_frame

    reference = escape_frame(pd.DataFrame(rows, columns=columns)).to_csv(index=False)
    assert buffer.getvalue() == reference


def _import_small_study(folder: Path, db: str) -> None:
    """Eight participants (4 novices, 4 experts), two trials per block, NASA-TLX:
    `study import`ed into the study database `db` (CSV files in `folder`)."""
    rng = np.random.default_rng(4)
    trials, tlx = [], []
    for k, group in enumerate(["novice"] * 4 + ["expert"] * 4):
        code = f"P{k + 1:03d}"
        for cond, shift in (("VO", 0.0), ("HV", -0.2)):
            for trial in (1, 2):
                row = [code, group, "lcca", cond, trial, 30 + rng.normal(0, 3)]
                trials.append([*row, 0.8 + shift + rng.normal(0, 0.05), 0.4, "true"])
            tlx.append([code, "lcca", cond, *[int(v) for v in rng.integers(4, 16, 6) * 5]])
            tlx[-1] += [5, 0, 3, 2, 4, 1]
    pd.DataFrame(trials, columns=TRIAL_COLUMNS).to_csv(folder / "t.csv", index=False)
    pd.DataFrame(tlx, columns=TLX_COLUMNS + TLX_WEIGHT_COLUMNS).to_csv(
        folder / "x.csv", index=False
    )
    argv = [
        "import",
        "--enrol-new",
        "--trials",
        str(folder / "t.csv"),
        "--tlx",
        str(folder / "x.csv"),
    ]
    assert main([*argv, "--db", db]) == 0


def test_study_analyze_on_postgresql_equals_sqlite(tmp_path: Path, pg_url: str) -> None:
    """The same study on both backends: the plain-SQL reading gives the same analysis
    through psycopg as through sqlite3."""
    from study.protocol.design import TEMPLATE

    db = init_study(tmp_path)
    _import_small_study(tmp_path, db)
    (tmp_path / "d.toml").write_text(TEMPLATE)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", pg_url]) == 0
    _import_small_study(tmp_path, pg_url)
    assert main(["analyze", "--out", str(tmp_path / "lite"), "--db", db]) == 0
    assert main(["analyze", "--out", str(tmp_path / "pg"), "--db", pg_url]) == 0
    for name in ("analysis.json", "tests.csv", "descriptives.csv", "lmm.tex"):
        lite = (tmp_path / "lite" / name).read_text()
        assert lite == (tmp_path / "pg" / name).read_text(), name


def test_study_analyze_reads_sqlite_alone_and_equals_the_sqlalchemy_path(
    tmp_path: Path,
) -> None:
    """The command on an SQLite file does not load SQLAlchemy (a fresh process; pandas,
    pyarrow, scipy and matplotlib come with statsmodels' mixed model and pingouin), and
    writes what the SQLAlchemy path writes (a URL with a parameter takes that path) and the
    frame API computes."""
    import subprocess
    import sys

    from study.analysis.frames import participant_means, tlx_frame, trial_frame
    from study.analysis.report import to_json
    from study.analysis.stats import analyze

    db = init_study(tmp_path)
    _import_small_study(tmp_path, db)
    probe = (
        "import sys\nfrom study.cli import main\n"
        f"assert main(['analyze', '--out', {str(tmp_path / 'plain')!r}, '--db', {db!r}]) == 0\n"
        "heavy = ('sqlalchemy', 'jinja2')\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"
    url = f"sqlite:///{db}?timeout=5"
    assert main(["analyze", "--out", str(tmp_path / "orm"), "--db", url]) == 0
    for name in ("analysis.json", "tests.csv", "comparisons.tex", "descriptives.csv"):
        plain = (tmp_path / "plain" / name).read_text()
        assert plain == (tmp_path / "orm" / name).read_text(), name
    from db.migrate import open_database

    engine = open_database(db, create=False)
    try:
        frames_trials, frames_tlx = trial_frame(engine), tlx_frame(engine)
    finally:
        engine.dispose()
    expected = to_json(analyze(frames_trials, participant_means(frames_trials, frames_tlx)))
    got = json.loads((tmp_path / "plain" / "analysis.json").read_text())
    assert got == json.loads(json.dumps(expected))


def test_type_ii_mixed_anova_equals_pingouin_on_unequal_groups() -> None:
    """pingouin.mixed_anova (Type II) as an independent reference on the 20/8/8 demo."""
    import pingouin

    from study.analysis.stats import mixed_anova_rows

    long = pd.read_csv(Path(__file__).parent.parent / "data" / "demo_seed1_means.csv")
    keys = ["participant", "group", "task", "condition", "measure", "value"]
    rows, _ = mixed_anova_rows(list(long[keys].itertuples(index=False, name=None)), ss_type=2)
    names = {"group": "group", "condition": "condition", "interaction": "Interaction"}
    for measure, data in long.groupby("measure"):
        ref = pingouin.mixed_anova(
            data, dv="value", within="condition", subject="participant", between="group"
        ).set_index("Source")
        for r in (r for r in rows if r["measure"] == measure):
            expected = ref.loc[names[r["source"]]]
            assert r["F"] == pytest.approx(expected["F"], rel=1e-10), (measure, r["source"])
            assert r["p"] == pytest.approx(expected["p_unc"], rel=1e-9)
            assert r["np2"] == pytest.approx(expected["np2"], rel=1e-10)
            assert (r["df1"], r["df2"]) == (expected["DF1"], expected["DF2"])


def test_study_analyze_computes_on_one_blas_thread(tmp_path: Path) -> None:
    """A fresh `study analyze` loads OpenBLAS with one thread (the models are small; more
    threads only spin beside the one computing), unless the user set another count."""
    import os
    import subprocess
    import sys

    db = init_study(tmp_path)
    _import_small_study(tmp_path, db)
    probe = (
        "from study.cli import main\n"
        "from threadpoolctl import threadpool_info\n"
        f"assert main(['analyze', '--out', {str(tmp_path / 'a')!r}, '--db', {db!r}]) == 0\n"
        "print([i['num_threads'] for i in threadpool_info() if i['internal_api'] == 'openblas'])\n"
    )
    env = {
        k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
    }
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, env=env
    )
    counts = json.loads(out.stdout.strip().splitlines()[-1])
    assert counts
    assert set(counts) == {1}
    env["OPENBLAS_NUM_THREADS"] = "2"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, env=env
    )
    assert set(json.loads(out.stdout.strip().splitlines()[-1])) == {2}
