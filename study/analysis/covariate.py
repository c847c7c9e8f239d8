"""A participant-level covariate (a probe's estimate of a trait) in the mixed model, and
the ANCOVA-style table read off it.

`study analyze --covariate NAME` (NAME a probe, `study.probes`, or the trait it tells):
each participant's estimate from their probe trials (`study.probes.measure`), centred
on the mean over the participants who have one, enters the linear mixed model of every
trial measure beside condition and group:

    value ~ condition * group + cov + condition:cov + (1 | participant)

(statsmodels `mixedlm`, REML, as `stats.mixed_model`; its fixed effects are lme4's
`lmer` on the same formula, which a test checks). The ANCOVA-style table gives, per
task and measure, the condition effect (HV - VO) adjusted to the mean covariate, the
covariate's slope, and the condition x covariate interaction (does the haptic benefit
change with the covariate?), each with its SE, Wald z p and 95 % interval. Participants
without the probe are left out of this model, and the note says who.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy import stats
from statsmodels.regression.mixed_linear_model import MixedLM

from study.errors import StudyInputError
from study.probes import probes

LMM_COLUMNS = ("task", "measure", "term", "estimate", "se", "p", "p_method")
ANCOVA_COLUMNS = (
    "task",
    "measure",
    "effect",
    "estimate",
    "se",
    "ci_low",
    "ci_high",
    "p",
    "participants",
    "covariate",
    "covariate_mean",
)
FORMULA = (
    "value ~ C(condition, Treatment('VO')) * C(group) + cov + C(condition, Treatment('VO')):cov"
)
CONDITION_TERM = "C(condition, Treatment('VO'))[T.HV]"
INTERACTION_TERM = "C(condition, Treatment('VO'))[T.HV]:cov"


def covariate_values(probe_trials: pd.DataFrame, name: str) -> tuple[str, pd.Series]:
    """(the trait, participant -> its probe estimate) for `name`, a probe or its trait;
    one line when no probe goes by that name or none of its trials are stored."""
    # lazy: study.probes.measure costs 7 ms at start-up
    from study.probes.measure import probe_table

    known = {p.name: p.trait for p in probes()}
    trait = known.get(name, name if name in known.values() else None)
    if trait is None:
        raise StudyInputError(
            f"--covariate {name!r}; expected a probe or its trait: "
            + ", ".join(f"{p} ({t})" for p, t in known.items())
        )
    table = probe_table(probe_trials) if len(probe_trials) else pd.DataFrame()
    if trait not in table or table[trait].notna().sum() == 0:
        raise StudyInputError(
            f"--covariate {name!r}: no participant has an estimate of {trait}; expected a "
            "study whose probes ran (`study probe run`)"
        )
    return trait, table[trait].dropna()


def _condition_effect(names: list[str]) -> dict[str, float]:
    """Weights of the fixed effects giving HV - VO averaged over the groups (treatment
    coding: the reference group's effect plus the mean of the others' interactions)."""
    groups = [n for n in names if n.startswith(f"{CONDITION_TERM}:C(group)")]
    weights = {CONDITION_TERM: 1.0}
    weights.update({n: 1.0 / (len(groups) + 1) for n in groups})
    return weights


def covariate_model(
    trials: pd.DataFrame, values: pd.Series, measures: dict[str, tuple[str, ...]], name: str
) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """(the mixed model's fixed effects, the ANCOVA-style table, notes) per task and
    measure (`measures`: task -> its analysed measures) with the covariate `values`
    (participant -> value)."""
    lmm_rows, ancova_rows, notes = [], [], []
    lacking = sorted(set(trials["participant"]) - set(values.index))
    if lacking:
        notes.append(f"covariate {name}: left out {', '.join(lacking)} (no probe estimate)")
    mean = float(values.mean())
    centred = values - mean
    for task, g in trials.groupby("task", sort=False):
        for measure in measures[task]:
            data = g[["participant", "group", "condition", measure]].dropna()
            data = data[data["participant"].isin(centred.index)]
            data = data.rename(columns={measure: "value"})
            data["cov"] = centred.reindex(data["participant"]).to_numpy()
            if data["participant"].nunique() < 4:
                notes.append(
                    f"{task}/{measure}: covariate model skipped (fewer than 4 participants)"
                )
                continue
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                try:
                    fit = MixedLM.from_formula(FORMULA, data, groups=data["participant"]).fit(
                        reml=True
                    )
                except (np.linalg.LinAlgError, ValueError) as exc:
                    notes.append(f"{task}/{measure}: covariate model could not be fitted: {exc}")
                    continue
            notes += [f"{task}/{measure}: covariate model warning: {w.message}" for w in caught]
            for term in fit.fe_params.index:
                lmm_rows.append(
                    {
                        "task": task,
                        "measure": measure,
                        "term": term,
                        "estimate": float(fit.fe_params[term]),
                        "se": float(fit.bse[term]),
                        "p": float(fit.pvalues[term]),
                        "p_method": "Wald z",
                    }
                )
            names = list(fit.fe_params.index)
            for effect, weights in (
                ("HV - VO at the mean covariate (mean over groups)", _condition_effect(names)),
                (f"slope of {name} in VO", {"cov": 1.0}),
                (f"HV - VO change per unit of {name}", {INTERACTION_TERM: 1.0}),
            ):
                contrast = np.array([[weights.get(n, 0.0) for n in names]])
                # the Wald test of L beta = 0 over the fixed effects
                test = fit.t_test(contrast)
                est, se = float(np.ravel(test.effect)[0]), float(np.ravel(test.sd)[0])
                z = stats.norm.ppf(0.975)
                ancova_rows.append(
                    {
                        "task": task,
                        "measure": measure,
                        "effect": effect,
                        "estimate": est,
                        "se": se,
                        "ci_low": est - z * se,
                        "ci_high": est + z * se,
                        "p": float(2 * stats.norm.sf(abs(est / se))),
                        "participants": int(data["participant"].nunique()),
                        "covariate": name,
                        "covariate_mean": mean,
                    }
                )
    return (
        pd.DataFrame(lmm_rows, columns=list(LMM_COLUMNS)),
        pd.DataFrame(ancova_rows, columns=list(ANCOVA_COLUMNS)),
        notes,
    )
