"""The mixed model against lme4, lmerTest, pbkrtest and emmeans on real human data
(lme4's sleepstudy, afex's stroop) and on the demo study's unequal groups (20/8/8).

The R references are evaluated at the exact REML optimum: lme4's optimiser stops about
1e-8 short of it, so theta is polished on lme4's own deviance function first:

    polish <- function(formula, d) {
      f0 <- lme4::lmer(formula, d, REML = TRUE)
      dev <- lme4::lmer(formula, d, REML = TRUE, devFunOnly = TRUE)
      t0 <- getME(f0, "theta")
      h <- seq(-0.01, 0.01, length.out = 41) * t0; y <- sapply(t0 + h, dev)
      cf <- coef(lm(y ~ h + I(h^2) + I(h^3)))
      r <- polyroot(c(cf[2], 2 * cf[3], 3 * cf[4])); th <- t0 + Re(r[which.min(abs(r))])
      lmerTest::lmer(formula, d, REML = TRUE, start = list(theta = th),
                     control = lmerControl(optimizer = NULL))
    }
    summary(f, ddf = "Satterthwaite")$coefficients; summary(f, ddf = "Kenward-Roger")
    e <- emmeans(f, ~ condition, lmer.df = "satterthwaite")   # or "kenward-roger"
    summary(pairs(e, reverse = TRUE), infer = TRUE)

R 4.2.2, lme4 1.1-31, lmerTest 3.1-3, pbkrtest 0.5.2, emmeans 1.8.4-1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.analysis.mixed_model import mixed_model
from study.analysis.stats_lmm import Design, fit_random_intercept

DATA = Path(__file__).parent.parent / "data"

# Reaction ~ Days + (1 | Subject) on lme4's sleepstudy (18 people x 10 days):
# theta 1.1978815282037778, sigma 30.991233909327882, REMLcrit 1786.4650853949211
SLEEP_SATT = [  # estimate, SE, df, p
    (251.40510484848437, 9.7467162422382625, 22.81019923041337, 2.241350057212461e-18),
    (10.46728595959596, 0.8042214292224851, 160.99999996840680, 6.412601472411976e-27),
]
SLEEP_KR = [(9.7467162422382643, 22.81019913669656), (0.8042214292224851, 161.00000000000003)]


def _sleep() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = pd.read_csv(DATA / "sleepstudy.csv")
    X = np.column_stack([np.ones(len(d)), d["Days"].to_numpy(float)])
    return X, d["Reaction"].to_numpy(float), d["Subject"].to_numpy()


def test_reml_fit_equals_lme4_and_statsmodels_likelihood_on_sleepstudy() -> None:
    import statsmodels.api as sm

    X, y, g = _sleep()
    fit = fit_random_intercept(X, y, g)
    assert fit.theta == pytest.approx(1.1978815282037778, rel=1e-8)  # R: cubic polish
    assert fit.sigma == pytest.approx(30.991233909327882, rel=1e-9)
    assert fit.reml_crit == pytest.approx(1786.4650853949211, rel=1e-12)
    # the deviance in (theta, sigma) is -2 x statsmodels' REML log-likelihood at its optimum
    model = sm.MixedLM(y, X, groups=Design.of(X, y, g).idx)
    model.fit(reml=True, method=["bfgs"])  # sets the penalties loglike reads
    assert -2 * model.loglike(np.array([fit.theta]), profile_fe=True) == pytest.approx(
        fit.reml_crit, rel=1e-12
    )
    for (est, se, _, _), b, s in zip(SLEEP_SATT, fit.beta, fit.se, strict=True):
        assert b == pytest.approx(est, rel=1e-12)
        assert s == pytest.approx(se, rel=1e-8)


@pytest.mark.parametrize("i", [0, 1])
def test_satterthwaite_and_kenward_roger_equal_lmertest_on_sleepstudy(i: int) -> None:
    fit = fit_random_intercept(*_sleep())
    L = np.eye(2)[i]
    _, _, df, p = SLEEP_SATT[i]
    s = fit.contrast(L)
    assert s.df == pytest.approx(df, rel=1e-6)
    assert s.p == pytest.approx(p, rel=1e-6)
    kr_se, kr_df = SLEEP_KR[i]
    k = fit.contrast(L, "Kenward-Roger")
    assert k.se == pytest.approx(kr_se, rel=1e-8)
    assert k.df == pytest.approx(kr_df, rel=1e-6)


# rt_s ~ condition * group + (1 | participant) on tests/data/stroop_subset.csv (afex's
# stroop, studies 1-3, 6/4/3 people, correct incongruent trials among the first 40):
# theta 0.73055306385626928, sigma 0.17407567337819735; unequal trials and groups.
STROOP_TERMS = [  # term, estimate, SE, Satterthwaite df, p; KR SE, KR df
    ("Intercept", 0.7082943131388596, 0.05684658757446279, 12.12458483821782,
     2.844720193801677e-08, 0.05685185921891294, 12.08786094472882),
    ("C(condition, Treatment('control'))[T.deplete]", 0.0008036631417941597,
     0.03136527708902803, 264.44896166436416, 9.795776026901289e-01, 0.03137048990327346,
     264.41966303572678),
    ("C(group)[T.study2]", 0.0706466632096906244, 0.08933777807652610, 11.84115617942929,
     4.446217468098819e-01, 0.08934149713856386, 11.80525205736643),
    ("C(group)[T.study3]", -0.0918242908869151414, 0.09729315981168829, 11.56879586634576,
     3.645706212116385e-01, 0.09729655446594451, 11.53368124760819),
    ("C(condition, Treatment('control'))[T.deplete]:C(group)[T.study2]",
     -0.0490867137601896306, 0.04960860701193519, 264.50429862182972,
     3.233327403717041e-01, 0.04961790319782949, 264.47516361480575),
    ("C(condition, Treatment('control'))[T.deplete]:C(group)[T.study3]",
     -0.0124359521198356190, 0.05180439097793413, 264.44030824470724,
     8.104728661788967e-01, 0.05181286170090038, 264.41098401816970),
]  # fmt: skip
# emmeans(f, ~ condition): (emmean, SE, df) Satterthwaite, then Kenward-Roger
STROOP_EMM = {
    "satt": [
        (0.7012351039131181, 0.03974315177756664, 11.59712203177355),
        (0.6815312117615705, 0.03973773504105051, 11.58893834998076),
    ],
    "kr": [
        (0.7012351039131181, 0.03974416620399560, 11.56192522321760),
        (0.6815312117615705, 0.03973938249396637, 11.55376528674077),
    ],
}
# pairs(e, reverse = TRUE): deplete - control, (estimate, SE, df, lower, upper, p)
STROOP_PAIR = {
    "satt": (-0.01970389215154759, 0.02150175240245362, 264.4761361781399,
             -0.06204028731116678, 0.0226325030080716, 0.360299611283192),
    "kr": (-0.01970389215154759, 0.02150555824436098, 264.4469178722639,
           -0.0620478024213733, 0.02264001811827812, 0.3603845801183801),
}  # fmt: skip


def _stroop(ddf: str) -> pd.DataFrame:
    d = pd.read_csv(DATA / "stroop_subset.csv").assign(task="stroop")
    table, notes = mixed_model(d, ("rt_s",), ddf=ddf)
    assert notes == []
    return table


def test_satterthwaite_equals_lmertest_on_unequal_groups_of_real_people() -> None:
    t = _stroop("Satterthwaite")
    coef = t[t["kind"] == "coefficient"].set_index("term")
    assert list(coef.index) == [r[0] for r in STROOP_TERMS]
    for term, est, se, df, p, _, _ in STROOP_TERMS:
        row = coef.loc[term]
        assert row["estimate"] == pytest.approx(est, rel=1e-9, abs=1e-10)
        assert row["se"] == pytest.approx(se, rel=1e-8)
        assert row["df"] == pytest.approx(df, rel=1e-6)
        assert row["p"] == pytest.approx(p, rel=1e-6)
        assert row["p_method"] == "Satterthwaite t"
        assert row["reference"] == "condition control, group study1"


def test_kenward_roger_equals_pbkrtest_on_unequal_groups() -> None:
    coef = _stroop("Kenward-Roger").query("kind == 'coefficient'").set_index("term")
    for term, *_, se, df in STROOP_TERMS:
        assert coef.loc[term, "se"] == pytest.approx(se, rel=1e-8)
        assert coef.loc[term, "df"] == pytest.approx(df, rel=1e-6)


@pytest.mark.parametrize("ddf", ["Satterthwaite", "Kenward-Roger"])
def test_marginal_means_equal_emmeans(ddf: str) -> None:
    key = "satt" if ddf == "Satterthwaite" else "kr"
    t = _stroop(ddf)
    means = t[t["kind"] == "marginal mean"]
    assert list(means["term"]) == ["mean control", "mean deplete"]
    for (est, se, df), (_, row) in zip(STROOP_EMM[key], means.iterrows(), strict=True):
        assert row["estimate"] == pytest.approx(est, rel=1e-9)
        assert row["se"] == pytest.approx(se, rel=1e-8)
        assert row["df"] == pytest.approx(df, rel=1e-6)
        assert row["p"] is None or np.isnan(row["p"])
    ((_, c),) = t[t["kind"] == "marginal contrast"].iterrows()
    est, se, df, lo, hi, p = STROOP_PAIR[key]
    assert c["term"] == "deplete - control"
    assert c["estimate"] == pytest.approx(est, rel=1e-9)
    assert c["se"] == pytest.approx(se, rel=1e-8)
    assert c["df"] == pytest.approx(df, rel=1e-6)
    assert c["ci_low"] == pytest.approx(lo, rel=1e-7)
    assert c["ci_high"] == pytest.approx(hi, rel=1e-7)
    assert c["p"] == pytest.approx(p, rel=1e-6)


# The demo study (20/8/8, 6 trials each): completion_time_s and peak_proximal_force_n.
# Satterthwaite (df, p) of Intercept, HV, novice, outsider, HV:novice, HV:outsider;
# emmeans HV - VO (estimate, SE, df, p): the within-participant df are exactly 177.
DEMO = {
    "completion_time_s": (
        [(50.16975289250230, 1.520292968253040e-09), (176.99999997324247, 2.844111170342931e-01),
         (50.16975286912030, 4.717181815313485e-02), (50.16975288430135, 2.628210792734357e-03),
         (176.99999998161866, 4.772622801592754e-01), (176.99999997109873, 7.127910449070352e-01)],
        (4.366111111111088, 1.450046149432894, 177.0),
    ),
    "peak_proximal_force_n": (
        [(91.97494453778629, 6.083537848450131e-17), (177.00000003015981, 2.918088124184952e-01),
         (91.97494454721956, 3.851516909626833e-01), (91.97494455358641, 3.107888494848120e-06),
         (177.00000002149568, 4.948630920309078e-01), (177.00000001883819, 7.945551061331878e-04)],
        (-0.2280801301235854, 0.04320413906573127, 177.0),
    ),
}  # fmt: skip


def test_demo_study_unequal_groups_equal_lmertest_and_emmeans() -> None:
    trials = pd.read_csv(DATA / "demo_seed1_trials.csv")
    table, _ = mixed_model(trials, tuple(DEMO))
    for measure, (coefs, (est, se, df)) in DEMO.items():
        got = table[table["measure"] == measure]
        rows = got[got["kind"] == "coefficient"]
        assert set(rows["reference"]) == {"condition VO, group expert"}
        for (df_r, p_r), (_, row) in zip(coefs, rows.iterrows(), strict=True):
            assert row["df"] == pytest.approx(df_r, rel=1e-6)
            assert row["p"] == pytest.approx(p_r, rel=1e-6)
        ((_, c),) = got[got["kind"] == "marginal contrast"].iterrows()
        assert c["term"] == "HV - VO"
        assert (c["estimate"], c["se"]) == (
            pytest.approx(est, rel=1e-9),
            pytest.approx(se, rel=1e-8),
        )
        assert c["df"] == pytest.approx(df, rel=1e-6)


def test_an_unknown_df_method_is_refused() -> None:
    from study.errors import StudyInputError

    trials = pd.read_csv(DATA / "demo_seed1_trials.csv")
    with pytest.raises(StudyInputError, match="'Wald'; expected one of Satterthwaite"):
        mixed_model(trials, ("completion_time_s",), ddf="Wald")


def _unequal_study(folder: Path) -> str:
    """An imported LCCA study of 4/3/2 people, one HV trial missing for some: unequal
    groups and cells, where Kenward-Roger's df differ from Satterthwaite's."""
    from study.cli import main
    from study.protocol.exchange import TRIAL_COLUMNS
    from tests.study.conftest import init_study

    db = init_study(folder)
    rng = np.random.default_rng(11)
    rows, k = [], 0
    for group, n in (("outsider", 4), ("novice", 3), ("expert", 2)):
        for _ in range(n):
            k += 1
            person = rng.normal(0, 4)
            for cond, shift in (("VO", 0.0), ("HV", -2.0)):
                for trial in (1, 2) if cond == "VO" or k % 2 else (1,):
                    time_s = 30 + person + shift + rng.normal(0, 2)
                    force = 0.8 + shift / 10 + rng.normal(0, 0.05)
                    rows.append(
                        [f"U{k:02d}", group, "lcca", cond, trial, time_s, force, 0.4, "true"]
                    )
    csv = folder / "t.csv"
    pd.DataFrame(rows, columns=TRIAL_COLUMNS).to_csv(csv, index=False)
    assert main(["import", "--enrol-new", "--trials", str(csv), "--db", db]) == 0
    return db


def test_analyze_ddf_option_reaches_the_mixed_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    from study.cli import main

    db = _unequal_study(tmp_path)
    reports = {}
    for ddf in ("satterthwaite", "kenward-roger", None):
        out = tmp_path / str(ddf)
        argv = ["analyze", "--out", str(out), "--db", db]
        assert main([*argv, "--ddf", ddf] if ddf else argv) == 0
        reports[ddf] = (
            json.loads((out / "analysis.json").read_text()),
            (out / "methods.md").read_text(),
        )
    names = {"satterthwaite": "Satterthwaite", "kenward-roger": "Kenward-Roger"}
    for ddf, name in names.items():
        report, methods = reports[ddf]
        assert report["methods"]["lmm"]["df"] == name
        assert f"t tests with {name} degrees of freedom" in methods
    assert reports[None][0]["lmm"] == reports["satterthwaite"][0]["lmm"]  # the default

    def df_of(report: dict) -> dict[tuple[str, str], float]:
        return {(r["measure"], r["term"]): r["df"] for r in report["lmm"]}

    sat, kr = df_of(reports["satterthwaite"][0]), df_of(reports["kenward-roger"][0])
    assert sat.keys() == kr.keys()
    assert any(abs(sat[k] - kr[k]) > 1e-3 for k in sat)  # the option changes the df
    capsys.readouterr()
    assert main(["analyze", "--out", str(tmp_path / "bad"), "--db", db, "--ddf", "wald"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    for word in ("'wald'", "satterthwaite", "kenward-roger"):
        assert word in err
    assert not (tmp_path / "bad").exists()
