"""The study's statistics on participant means (seed 000, IV-D; the analysis issue).

- `descriptives`: per task, measure, group and condition: n, mean, SD, median, IQR and
  the t-based 95 % confidence interval of the mean.
- `compare_conditions`: VO against HV within each group on paired participant means.
  Shapiro-Wilk on the differences (alpha .05) picks a paired t-test (effect size Hedges'
  g_av, Lakens 2013: d_av = mean difference / mean of the two SDs, times Hedges'
  correction 1 - 3 / (4 (2n) - 9)) or the Wilcoxon signed-rank test (effect size the
  matched-pairs rank-biserial correlation, Kerby 2014). Holm's correction runs across the
  groups of one task x measure (pingouin's `multicomp`; statsmodels' `multipletests`
  gives the same values but runs a garbage collection on every call, 0.2 s each).
- `mixed_anova`: group (between) x condition (within), pingouin's `mixed_anova` with
  partial eta squared; unequal group sizes are allowed (its sums of squares are for
  unbalanced between-subject groups) and the sizes are stated.
- `mixed_model`: a linear mixed model over all trials, value ~ condition * group with a
  random intercept per participant (statsmodels `mixedlm`, REML); convergence warnings
  are returned with the table, never hidden.

Participants without both conditions of a comparison are excluded from it, and each
exclusion is stated.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
import pingouin as pg
import statsmodels.formula.api as smf
from scipy import stats

ALPHA = 0.05
COMPARISON_COLUMNS = (
    "task", "measure", "group", "n", "mean_vo", "mean_hv", "sd_vo", "sd_hv", "shapiro_p",
    "test", "statistic", "p", "effect_size", "effect_size_kind", "p_holm",
)  # fmt: skip


@dataclass
class Analysis:
    descriptives: pd.DataFrame
    comparisons: pd.DataFrame
    mixed_anova: pd.DataFrame
    lmm: pd.DataFrame
    exclusions: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def descriptives(long: pd.DataFrame) -> pd.DataFrame:
    """Columns: task, measure, group, condition, n, mean, sd, median, iqr, ci_low, ci_high."""
    rows = []
    for (task, measure, group, condition), g in long.groupby(
        ["task", "measure", "group", "condition"], sort=False
    ):
        x = g["value"].to_numpy(float)
        n = len(x)
        mean = float(np.mean(x))
        sd = float(np.std(x, ddof=1)) if n > 1 else float("nan")
        half = float(stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n)) if n > 1 else float("nan")
        q1, q3 = np.percentile(x, [25, 75])
        rows.append(
            {
                "task": task, "measure": measure, "group": group, "condition": condition,
                "n": n, "mean": mean, "sd": sd, "median": float(np.median(x)),
                "iqr": float(q3 - q1), "ci_low": mean - half, "ci_high": mean + half,
            }
        )  # fmt: skip
    return pd.DataFrame(rows)


def hedges_g_av(vo: np.ndarray, hv: np.ndarray) -> float:
    """Lakens (2013) eq. 10 with Hedges' correction: d_av (1 - 3 / (4 (n1 + n2) - 9))."""
    n = len(vo)
    sd_av = (np.std(vo, ddof=1) + np.std(hv, ddof=1)) / 2
    if sd_av == 0:
        return float("nan")  # no spread: no standardised effect
    d_av = (np.mean(hv) - np.mean(vo)) / sd_av
    return float(d_av * (1 - 3 / (4 * (2 * n) - 9)))


def rank_biserial(vo: np.ndarray, hv: np.ndarray) -> float:
    """Matched-pairs rank-biserial correlation of HV - VO (Kerby 2014): (R+ - R-) / total."""
    d = hv - vo
    d = d[d != 0]
    ranks = stats.rankdata(np.abs(d))
    total = ranks.sum()
    return float((ranks[d > 0].sum() - ranks[d < 0].sum()) / total) if total else 0.0


def compare_conditions(
    long: pd.DataFrame, a: str = "VO", b: str = "HV"
) -> tuple[pd.DataFrame, list[str]]:
    rows, excluded = [], []
    # one pivot for everything (a pivot per group costs more than all the tests)
    keys = ["task", "measure", "group", "participant"]
    everything = long.pivot_table(index=keys, columns="condition", values="value", sort=False)
    for c in (a, b):
        if c not in everything:
            everything[c] = np.nan
    for (task, measure, group), wide in everything.groupby(level=[0, 1, 2], sort=False):
        wide = wide.droplevel([0, 1, 2])
        missing = wide[wide[[a, b]].isna().any(axis=1)].index.tolist()
        if missing:
            excluded.append(
                f"{task}/{measure}/{group}: excluded {', '.join(missing)} (missing {a} or {b})"
            )
        wide = wide.dropna(subset=[a, b])
        n = len(wide)
        row: dict[str, Any] = {"task": task, "measure": measure, "group": group, "n": n}
        if n < 3:
            excluded.append(f"{task}/{measure}/{group}: n = {n} pairs, too few to test")
            continue
        vo, hv = wide[a].to_numpy(float), wide[b].to_numpy(float)
        diff = hv - vo
        normal_p = float(stats.shapiro(diff).pvalue) if np.ptp(diff) > 0 else 1.0
        row.update(
            mean_vo=float(vo.mean()), mean_hv=float(hv.mean()),
            sd_vo=float(vo.std(ddof=1)), sd_hv=float(hv.std(ddof=1)), shapiro_p=normal_p,
        )  # fmt: skip
        if normal_p >= ALPHA:
            t = stats.ttest_rel(hv, vo)
            row.update(
                test="paired_t",
                statistic=float(t.statistic),
                p=float(t.pvalue),
                effect_size=hedges_g_av(vo, hv),
                effect_size_kind="hedges_g_av",
            )
        else:
            if np.all(diff == 0):
                w_stat, w_p = 0.0, 1.0
            else:
                w = stats.wilcoxon(hv, vo)
                w_stat, w_p = float(w.statistic), float(w.pvalue)
            row.update(
                test="wilcoxon",
                statistic=w_stat,
                p=w_p,
                effect_size=rank_biserial(vo, hv),
                effect_size_kind="rank_biserial",
            )
        rows.append(row)
    frame = pd.DataFrame(rows, columns=list(COMPARISON_COLUMNS))
    if len(frame):
        for _, idx in frame.groupby(["task", "measure"]).groups.items():
            frame.loc[idx, "p_holm"] = pg.multicomp(frame.loc[idx, "p"].to_numpy(), method="holm")[
                1
            ]
    return frame, excluded


def _sizes(counts: pd.Series) -> str:
    return ", ".join(f"{g} {int(n)}" for g, n in counts.items())


def mixed_anova(long: pd.DataFrame, a: str = "VO", b: str = "HV") -> tuple[pd.DataFrame, list[str]]:
    rows, notes = [], []
    for (task, measure), g in long.groupby(["task", "measure"], sort=False):
        both = g.groupby("participant")["condition"].nunique()
        keep = both[both == 2].index
        g = g[g["participant"].isin(keep)]
        sizes = g.drop_duplicates("participant")["group"].value_counts()
        if len(sizes) < 2 or (sizes < 2).any():
            notes.append(f"{task}/{measure}: mixed ANOVA skipped (groups {_sizes(sizes)})")
            continue
        if sizes.nunique() > 1:
            notes.append(
                f"{task}/{measure}: unequal group sizes {_sizes(sizes)}; pingouin's mixed ANOVA "
                "handles unbalanced between-subject groups"
            )
        try:
            table = pg.mixed_anova(
                data=g, dv="value", within="condition", subject="participant", between="group"
            )
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError) as exc:
            notes.append(f"{task}/{measure}: mixed ANOVA could not be computed: {exc}")
            continue
        names = {"group": "group", "condition": "condition", "Interaction": "interaction"}
        for _, r in table.iterrows():
            rows.append(
                {
                    "task": task, "measure": measure, "source": names[r["Source"]],
                    "F": float(r["F"]), "df1": float(r["DF1"]), "df2": float(r["DF2"]),
                    "p": float(r["p_unc"] if "p_unc" in r else r["p-unc"]), "np2": float(r["np2"]),
                }
            )  # fmt: skip
    return pd.DataFrame(
        rows, columns=["task", "measure", "source", "F", "df1", "df2", "p", "np2"]
    ), notes


def mixed_model(trials: pd.DataFrame, measures: tuple[str, ...]) -> tuple[pd.DataFrame, list[str]]:
    rows, notes = [], []
    for task, g in trials.groupby("task", sort=False):
        for measure in measures:
            data = g[["participant", "group", "condition", measure]].dropna()
            data = data.rename(columns={measure: "value"})
            if data["participant"].nunique() < 3:
                notes.append(f"{task}/{measure}: mixed model skipped (fewer than 3 participants)")
                continue
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                try:
                    model = smf.mixedlm(
                        "value ~ C(condition, Treatment('VO')) * C(group)",
                        data,
                        groups=data["participant"],
                    )
                    fit = model.fit(reml=True)
                except (np.linalg.LinAlgError, ValueError) as exc:
                    notes.append(f"{task}/{measure}: mixed model could not be fitted: {exc}")
                    continue
            for w in caught:
                notes.append(f"{task}/{measure}: mixed model warning: {w.message}")
            for term in fit.fe_params.index:
                rows.append(
                    {
                        "task": task, "measure": measure, "term": term,
                        "estimate": float(fit.fe_params[term]), "se": float(fit.bse[term]),
                        "p": float(fit.pvalues[term]),
                    }
                )  # fmt: skip
    return pd.DataFrame(rows, columns=["task", "measure", "term", "estimate", "se", "p"]), notes


def _missing_questionnaires(trials: pd.DataFrame, long: pd.DataFrame) -> list[str]:
    notes = []
    tlx = long[long["measure"].str.startswith("tlx_")]
    for task, g in trials.groupby("task", sort=False):
        answered = set(tlx.loc[tlx["task"] == task, "participant"])
        missing = sorted(set(g["participant"]) - answered)
        if missing:
            notes.append(f"{task}/tlx_*: excluded {', '.join(missing)} (no questionnaires)")
    return notes


def analyze(trials: pd.DataFrame, long: pd.DataFrame) -> Analysis:
    comparisons, excluded = compare_conditions(long)
    excluded = _missing_questionnaires(trials, long) + excluded
    anova, anova_notes = mixed_anova(long)
    lmm, lmm_notes = mixed_model(trials, ("completion_time_s", "peak_proximal_force_n",
                                          "peak_distal_force_n"))  # fmt: skip
    return Analysis(
        descriptives=descriptives(long),
        comparisons=comparisons,
        mixed_anova=anova,
        lmm=lmm,
        exclusions=excluded,
        warnings=anova_notes + lmm_notes,
    )
