"""The crossover's checks against lmerTest and emmeans, on the 20/8/8 study with a period
effect (10 % of the mean) and a carry-over (20 %) planted (`crossover_csv`, seed 0):
each check's estimate, Satterthwaite df and p, the condition's marginal contrast after
the terms are added, and the fit after, equal R's within 1e-6 relative.

R 4.2.2, lme4 1.1-31, lmerTest 3.1-3, emmeans 1.8.4-1, on the CSV the test writes
(`crossover_trials(0, period=0.1, carry_over=0.2)`), bobyqa run to the optimum
(`lmerControl(optimizer = "bobyqa", optCtrl = list(rhobeg = 2e-4, rhoend = 1e-12,
maxfun = 1e5))`, written `ctl` below):

    d$later <- as.numeric(d$block > 1)                        # the period term
    d$carry <- d$later * (d$condition == "VO")                # VO after HV
    d$pos <- d$trial - ave(d$trial, d$participant, d$block)   # trial position, centred
    d$condition <- factor(d$condition, levels = c("VO", "HV"))
    f1 <- lmer(completion_time_s ~ group * condition + later + pos + (1 | participant),
               d, REML = TRUE, control = ctl)
    summary(f1)$coefficients[c("later", "pos"), ]
    #       Estimate         Std. Error     df             t value          Pr(>|t|)
    # later  6.4840555555556 0.405211838912 175.000000446  16.00164391290   4.32185194159e-36
    # pos   -0.0354652777778 0.248140560767 175.000000445  -0.14292414617   8.86514516933e-01
    f2 <- lmer(completion_time_s ~ group * condition + later + carry + pos + (1 | participant),
               d, REML = TRUE, control = ctl)
    summary(f2)$coefficients["carry", ]
    # 11.2354814815 2.10316213796 32.0000000727 5.34218512147 7.34108447934e-06
    f3 <- lmer(completion_time_s ~ group * condition + later + carry + (1 | participant),
               d, REML = TRUE, control = ctl)
    summary(contrast(emmeans(f3, ~ condition, lmer.df = "satterthwaite"), "revpairwise"),
            infer = TRUE)
    # HV - VO 1.36585462963 SE 1.14094786143 df 44.093048848
    #         CI -0.933437647957 3.66514690722, p 0.237655338679
    sigma(f3); as.data.frame(VarCorr(f3))$sdcor[1]; REMLcrit(f3)
    # 2.96938864583  2.91253490880  1131.73870765
"""

from __future__ import annotations

import pytest

from study.analysis.crossover import design_checks
from tests.study.crossover_csv import crossover_trials

REL = 1e-6


@pytest.fixture(scope="module")
def result():
    return design_checks(
        crossover_trials(0, period=0.1, carry_over=0.2), measures=("completion_time_s",)
    )


@pytest.mark.parametrize(
    ("effect", "estimate", "p"),
    [
        ("period", 6.4840555555556, 4.32185194159e-36),
        ("trial_position", -0.0354652777778, 8.86514516933e-01),
        ("carry_over", 11.2354814815, 7.34108447934e-06),
    ],
)
def test_each_check_equals_lmertest(result, effect: str, estimate: float, p: float) -> None:
    check = next(c for c in result.checks if c["effect"] == effect)
    assert check["estimate"] == pytest.approx(estimate, rel=REL)
    assert check["p"] == pytest.approx(p, rel=REL)


def test_the_condition_after_and_the_fit_after_equal_emmeans_and_lme4(result) -> None:
    check = next(c for c in result.checks if c["effect"] == "carry_over")
    after = check["condition_after"]
    assert after["estimate"] == pytest.approx(1.36585462963, rel=REL)
    assert after["df"] == pytest.approx(44.093048848, rel=REL)
    assert after["ci"] == pytest.approx([-0.933437647957, 3.66514690722], rel=REL)
    assert after["p"] == pytest.approx(0.237655338679, rel=REL)
    (fit,) = result.fits
    assert fit["added"] == ["period", "carry_over"]
    assert fit["fit_after"]["residual_sd"] == pytest.approx(2.96938864583, rel=REL)
    assert fit["fit_after"]["participant_sd"] == pytest.approx(2.91253490880, rel=REL)
    assert fit["fit_after"]["reml_criterion"] == pytest.approx(1131.73870765, rel=REL)
