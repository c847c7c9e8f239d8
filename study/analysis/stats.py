"""The study's statistics on participant means ([endovascular], IV-D; the analysis issue).

- `descriptives`: per task, measure, group and condition: n, mean, SD, median, IQR and
  the t-based 95 % confidence interval of the mean.
- `compare_conditions`: VO against HV within each group on paired participant means.
  Shapiro-Wilk on the differences (alpha .05) picks a paired t-test (effect size Hedges'
  g_av, Lakens 2013: d_av = mean difference / mean of the two SDs, times Hedges'
  correction 1 - 3 / (4 (2n) - 9)) or the Wilcoxon signed-rank test (effect size the
  matched-pairs rank-biserial correlation, Kerby 2014; exact or asymptotic p by R's
  `wilcox.test` rule on the differences at the data's resolution,
  `wilcoxon_signed_rank`). Holm's correction runs across the groups of one task x
  measure (`holm`, pingouin's `multicomp(method="holm")` line for line: importing
  pingouin for it cost 2.3 s of `study analyze`'s start; statsmodels' `multipletests`
  gives the same values but runs a garbage collection on every call, 0.2 s each).
- `mixed_anova`: group (between) x condition (within) with partial eta squared and
  Type II (default) or Type III sums of squares, equal to R's afex `aov_ez(type = 2|3)`.
  pingouin's `mixed_anova` has Type II only, so both come from two one-way models in
  closed form (`anova.py` says how); unequal group sizes are stated.
- `mixed_model`: a linear mixed model over all trials, value ~ condition * group with a
  random intercept per participant, REML at the exact optimum (`stats_lmm`, equal to
  lme4); its p-values are Wald z tests (no Satterthwaite df; lmerTest's are a little
  larger on small samples). A singular fit (lme4's `isSingular`) is noted with the table.

Participants without both conditions of a comparison are excluded from it, and each
exclusion is stated.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from study.analysis.anova import anova_rows
from study.analysis.source import DRIVERS, DataSource
from study.errors import StudyInputError

ALPHA = 0.05
COMPARISON_COLUMNS = (
    "task",
    "measure",
    "group",
    "n",
    "mean_vo",
    "mean_hv",
    "sd_vo",
    "sd_hv",
    "shapiro_p",
    "test",
    "statistic",
    "p",
    "effect_size",
    "effect_size_kind",
    "p_holm",
    "p_method",
)
EXACT_MAX_N = 50
"""The Wilcoxon p is exact below this many non-zero differences (R's `wilcox.test`)."""
ANOVA_COLUMNS = ("task", "measure", "source", "F", "df1", "df2", "p", "np2", "ss_type")


@dataclass
class Analysis:
    """The study's analysis: its tables, notes and data source (`analyze` returns it).

    Attributes
    ----------
    descriptives
        `descriptives` of the participant means.
    comparisons
        `compare_conditions`' tests, `COMPARISON_COLUMNS`.
    mixed_anova
        `mixed_anova`'s table, `ANOVA_COLUMNS`.
    lmm
        `mixed_model`'s fixed effects.
    exclusions
        Who was left out of which test, and why (one line each).
    warnings
        Notes of the ANOVA and the mixed model (skipped fits, unequal groups, boundary).
    """

    descriptives: pd.DataFrame
    comparisons: pd.DataFrame
    mixed_anova: pd.DataFrame
    lmm: pd.DataFrame
    exclusions: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    source: DataSource = field(default_factory=lambda: DataSource(dict.fromkeys(DRIVERS, 0)))
    """The analysed trials by driver; every output says when they are simulated."""
    ss_type: int = 2
    """Sums-of-squares type of the mixed ANOVA."""

    @property
    def tasks(self) -> list[str]:
        frames = (self.descriptives, self.comparisons, self.mixed_anova, self.lmm)
        return list(dict.fromkeys(t for f in frames if len(f) for t in f["task"]))

    def warnings_about(self, kind: str) -> list[str]:
        """The notes of one analysis ('mixed ANOVA', 'mixed model')."""
        return [w for w in self.warnings if kind in w]

    def for_task(self, task: str) -> Analysis:
        """The same analysis restricted to one task (its tables, notes and exclusions)."""

        def keep(frame: pd.DataFrame) -> pd.DataFrame:
            return frame[frame["task"] == task].reset_index(drop=True) if len(frame) else frame

        return Analysis(
            descriptives=keep(self.descriptives),
            comparisons=keep(self.comparisons),
            mixed_anova=keep(self.mixed_anova),
            lmm=keep(self.lmm),
            exclusions=[e for e in self.exclusions if e.startswith(f"{task}/")],
            warnings=[w for w in self.warnings if w.startswith(f"{task}/")],
            source=self.source,
            ss_type=self.ss_type,
        )


def descriptives(long: pd.DataFrame) -> pd.DataFrame:
    """Descriptive statistics of the participant means.

    Parameters
    ----------
    long
        One row per participant, task, measure and condition: columns task, measure,
        group, condition, participant, value.

    Returns
    -------
    pandas.DataFrame
        Per task, measure, group and condition: n, mean, sd, median, iqr and the
        t-based 95 % interval of the mean (ci_low, ci_high); NaN where n = 1.
    """
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
                "task": task,
                "measure": measure,
                "group": group,
                "condition": condition,
                "n": n,
                "mean": mean,
                "sd": sd,
                "median": float(np.median(x)),
                "iqr": float(q3 - q1),
                "ci_low": mean - half,
                "ci_high": mean + half,
            }
        )
    return pd.DataFrame(rows)


def hedges_g_av(vo: np.ndarray, hv: np.ndarray) -> float:
    """Hedges' g_av of paired samples [lakens2013].

    Parameters
    ----------
    vo, hv
        The participants' values in the two conditions, paired by position.

    Returns
    -------
    float
        Lakens' eq. 10 with Hedges' correction, d_av (1 - 3 / (4 (n1 + n2) - 9)), of
        HV - VO; NaN when neither condition has any spread.
    """
    n = len(vo)
    sd_av = (np.std(vo, ddof=1) + np.std(hv, ddof=1)) / 2
    if sd_av == 0:
        return float("nan")  # no spread: no standardised effect
    d_av = (np.mean(hv) - np.mean(vo)) / sd_av
    return float(d_av * (1 - 3 / (4 * (2 * n) - 9)))


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values of one family; NaN stays NaN and is no member.

    Parameters
    ----------
    p : Float1D
        Unadjusted p-values, NaN for a test that could not be run.

    Returns
    -------
    Float1D
        Adjusted p-values, same order, at most 1: the running maximum of the sorted
        finite p-values times m, m - 1, ..., 1 (pingouin's `multicomp(method="holm")`).

    >>> holm(np.array([0.01, np.nan, 0.04, 0.03])).tolist()
    [0.03, nan, 0.06, 0.06]
    """
    p = np.asarray(p, dtype=float)
    valid = ~np.isnan(p)
    adjusted = np.full(p.shape, np.nan)
    finite = p[valid]
    order = np.argsort(finite)
    corrected = np.empty(finite.size)
    # p_(i) (m - i + 1), then a running maximum so that adjusted p-values keep the order
    corrected[order] = np.maximum.accumulate(finite[order] * np.arange(finite.size, 0, -1))
    adjusted[valid] = np.clip(corrected, None, 1)
    return adjusted


RESOLUTION_REL = 1e-9
"""Two differences closer than this times the data's magnitude are equal (and a difference
that small is zero): measures on a grid (0.01 s) differ by rounding noise (1.2 s comes out
as 1.1999999999999957 and 1.1999999999999993), which must not decide zeros, ties, ranks
and so whether the Wilcoxon p is exact."""


def at_resolution(diff: np.ndarray, scale: float | None = None) -> np.ndarray:
    """`diff` with rounding noise removed: values within `RESOLUTION_REL` x `scale` (the
    magnitude of the data the differences came from; default the largest |diff|) of zero
    become 0, and runs of |values| that close become one value (the run's first), so that
    ties and zeros are those of the data's resolution.

    >>> d = at_resolution(np.array([1.1999999999999993, -1.1999999999999957, 1e-15]), 30.0)
    >>> bool(d[0] == -d[1]), float(d[2])
    (True, 0.0)
    """
    d = np.asarray(diff, dtype=float)
    if not d.size:
        return d.copy()
    size = np.abs(d)
    tol = RESOLUTION_REL * (float(size.max()) if scale is None else float(scale))
    order = np.argsort(size, kind="stable")
    snapped = size[order].copy()
    anchor = 0.0  # the run's value; zero first, so that tiny differences are zeros
    for i, v in enumerate(snapped):
        if v - anchor > tol:
            anchor = v
        snapped[i] = anchor
    out = np.empty_like(d)
    out[order] = snapped
    return np.sign(d) * out


def rank_biserial(vo: np.ndarray, hv: np.ndarray) -> float:
    """Matched-pairs rank-biserial correlation of HV - VO [kerby2014].

    Parameters
    ----------
    vo, hv
        The participants' values in the two conditions, paired by position.

    Returns
    -------
    float
        (R+ - R-) / total over the ranks of the non-zero differences, taken at the
        data's resolution (`at_resolution`); 0 when every difference is zero.
    """
    d = at_resolution(hv - vo, _magnitude(vo, hv))
    d = d[d != 0]
    ranks = stats.rankdata(np.abs(d))
    total = ranks.sum()
    return float((ranks[d > 0].sum() - ranks[d < 0].sum()) / total) if total else 0.0


def _magnitude(vo: np.ndarray, hv: np.ndarray) -> float:
    return float(max(np.abs(vo).max(initial=0.0), np.abs(hv).max(initial=0.0)))


def wilcoxon_signed_rank(diff: np.ndarray, scale: float | None = None) -> tuple[float, float, str]:
    """Two-sided Wilcoxon signed-rank test of paired differences: (V, p, method).

    The differences are first taken at the data's resolution (`at_resolution`, `scale`
    the magnitude of the measured values), so zeros and ties are those of the data, not
    of floating-point noise. The rule is R's `wilcox.test` default, written out so that it
    does not depend on the scipy version (scipy's `method="auto"` changed between
    releases): the p-value is exact when there are fewer than 50 differences, none zero
    and no two of equal size; otherwise zero differences are dropped (Wilcoxon's
    convention) and p is the normal approximation with the tie-corrected variance and a
    continuity correction ("asymptotic"). V is R's statistic: the sum of the ranks of the
    positive differences (scipy reports min(R+, R-) instead).

    Parameters
    ----------
    diff
        The paired differences (HV - VO).
    scale
        The magnitude of the measured values (default the largest |diff|).

    Returns
    -------
    tuple of (float, float, str)
        V, the two-sided p-value, and the method, ``"exact"`` or ``"asymptotic"``.
    """
    full = at_resolution(diff, scale)
    d = full[full != 0]
    if not len(d):
        return 0.0, 1.0, "exact"
    ties = len(np.unique(np.abs(d))) < len(d)
    exact = len(d) == len(full) and len(d) < EXACT_MAX_N and not ties
    method = "exact" if exact else "asymptotic"
    w = stats.wilcoxon(d, method=method, correction=method == "asymptotic")
    v = float(stats.rankdata(np.abs(d))[d > 0].sum())
    return v, float(w.pvalue), method


def compare_conditions(
    long: pd.DataFrame, a: str = "VO", b: str = "HV"
) -> tuple[pd.DataFrame, list[str]]:
    """Condition `b` against `a` per task, measure and group, on participant means.

    A paired t test with Hedges' g_av where the differences pass Shapiro-Wilk at
    `ALPHA`, else the Wilcoxon signed-rank test with the rank-biserial correlation; the
    p-values of the groups of one task and measure are Holm-adjusted together.

    Parameters
    ----------
    long
        One row per participant, task, measure and condition (columns task, measure,
        group, condition, participant, value).
    a, b
        The two conditions.

    Returns
    -------
    tuple of (pandas.DataFrame, list of str)
        The tests (`COMPARISON_COLUMNS`), and the exclusions: participants without both
        conditions, and groups with fewer than 3 pairs (not tested).
    """
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
            mean_vo=float(vo.mean()),
            mean_hv=float(hv.mean()),
            sd_vo=float(vo.std(ddof=1)),
            sd_hv=float(hv.std(ddof=1)),
            shapiro_p=normal_p,
        )
        if normal_p >= ALPHA:
            t = stats.ttest_rel(hv, vo)
            row.update(
                test="paired_t",
                statistic=float(t.statistic),
                p=float(t.pvalue),
                effect_size=hedges_g_av(vo, hv),
                effect_size_kind="hedges_g_av",
                p_method="t distribution",
            )
        else:
            w_stat, w_p, method = wilcoxon_signed_rank(diff, _magnitude(vo, hv))
            row.update(
                test="wilcoxon",
                statistic=w_stat,
                p=w_p,
                effect_size=rank_biserial(vo, hv),
                effect_size_kind="rank_biserial",
                p_method=method,
            )
        rows.append(row)
    frame = pd.DataFrame(rows, columns=list(COMPARISON_COLUMNS))
    if len(frame):
        for _, idx in frame.groupby(["task", "measure"]).groups.items():
            frame.loc[idx, "p_holm"] = holm(frame.loc[idx, "p"].to_numpy())
    return frame, excluded


def _sizes(counts: pd.Series) -> str:
    return ", ".join(f"{g} {int(n)}" for g, n in counts.items())


SS_TYPES = (2, 3)
DEFAULT_SS_TYPE = 2
"""Type II by default: with unequal groups it tests the condition effect on the
participant-weighted mean (pingouin's `mixed_anova`, R `afex::aov_ez(type = 2)`); Type III
(afex's default, `type = 3`, sum contrasts) tests it on the unweighted mean of the group
means. The group and interaction terms are the same under both."""


def mixed_anova(
    long: pd.DataFrame, a: str = "VO", b: str = "HV", ss_type: int = DEFAULT_SS_TYPE
) -> tuple[pd.DataFrame, list[str]]:
    """Group x condition mixed ANOVA per task x measure, with Type II or III sums of squares.

    Parameters
    ----------
    long
        One row per participant, task, measure and condition (columns task, measure,
        group, condition, participant, value).
    a, b
        The two conditions.
    ss_type
        2 or 3 (`DEFAULT_SS_TYPE` says why 2 by default).

    Returns
    -------
    tuple of (pandas.DataFrame, list of str)
        Columns task, measure, source (group, condition, interaction), F, df1, df2, p,
        np2 (partial eta squared), ss_type; and notes (skipped analyses, unequal sizes).

    Raises
    ------
    StudyInputError
        `ss_type` is neither 2 nor 3.
    """
    if ss_type not in SS_TYPES:
        raise StudyInputError(f"sums-of-squares type {ss_type!r}; expected 2 or 3")
    rows, notes = [], []
    pairs = long[long["condition"].isin((a, b))]
    for (task, measure), g in pairs.groupby(["task", "measure"], sort=False):
        wide = g.pivot_table(
            index=["participant", "group"], columns="condition", values="value"
        ).reset_index()
        wide = wide.dropna(subset=[c for c in (a, b) if c in wide])
        sizes = wide["group"].value_counts(sort=False) if {a, b} <= set(wide) else pd.Series()
        if len(sizes) < 2 or (sizes < 2).any():
            notes.append(f"{task}/{measure}: mixed ANOVA skipped (groups {_sizes(sizes)})")
            continue
        if sizes.nunique() > 1:
            notes.append(
                f"{task}/{measure}: mixed ANOVA on unequal group sizes {_sizes(sizes)}, "
                f"Type {'II' if ss_type == 2 else 'III'} sums of squares"
            )
        if (wide.groupby("group")[[a, b]].var() == 0).all().all():
            notes.append(f"{task}/{measure}: mixed ANOVA skipped (no variance within groups)")
            continue
        for row in anova_rows(wide, a, b, ss_type):
            rows.append({"task": task, "measure": measure, **row})
    return pd.DataFrame(rows, columns=ANOVA_COLUMNS), notes


CONDITION_TERM = "C(condition, Treatment('VO'))"


def lmm_design(data: pd.DataFrame) -> tuple[np.ndarray, list[str]]:
    """The fixed-effects design of value ~ condition * group.

    Parameters
    ----------
    data
        One row per trial, with columns condition and group.

    Returns
    -------
    tuple of (numpy.ndarray, list of str)
        The design matrix (treatment coding, VO and the alphabetically first group as
        reference) and its columns' names as patsy names them.
    """
    conditions = [c for c in sorted(data["condition"].unique()) if c != "VO"]
    groups = sorted(data["group"].unique())[1:]
    cond = {c: (data["condition"] == c).to_numpy(float) for c in conditions}
    grp = {g: (data["group"] == g).to_numpy(float) for g in groups}
    columns, names = [np.ones(len(data))], ["Intercept"]
    for c in conditions:
        columns.append(cond[c])
        names.append(f"{CONDITION_TERM}[T.{c}]")
    for g in groups:
        columns.append(grp[g])
        names.append(f"C(group)[T.{g}]")
    for g in groups:
        for c in conditions:
            columns.append(cond[c] * grp[g])
            names.append(f"{CONDITION_TERM}[T.{c}]:C(group)[T.{g}]")
    return np.column_stack(columns), names


def mixed_model(
    trials: pd.DataFrame, measures: tuple[str, ...] | None = None
) -> tuple[pd.DataFrame, list[str]]:
    """The linear mixed model of every trial measure (default: each task's analysed
    measures, `study.protocol.tasks`), per task: REML with a random intercept per
    participant (`stats_lmm`, lme4's optimum); p from Wald z tests. A fit on the boundary
    (lme4's `isSingular`) is noted.

    Parameters
    ----------
    trials
        One row per measured trial: participant, group, task, condition and the
        measures.
    measures
        The measures to model (default: each task's analysed measures).

    Returns
    -------
    tuple of (pandas.DataFrame, list of str)
        The fixed effects (task, measure, term, estimate, se, p, p_method), and notes (skipped
        or singular fits).
    """
    from study.analysis.stats_lmm import SINGULAR_TOL, fit_random_intercept
    from study.protocol.tasks import get_task

    rows, notes = [], []
    for task, g in trials.groupby("task", sort=False):
        for measure in measures or get_task(task).analysed_measures:
            data = g[["participant", "group", "condition", measure]].dropna()
            data = data.rename(columns={measure: "value"})
            if data["participant"].nunique() < 3:
                notes.append(f"{task}/{measure}: mixed model skipped (fewer than 3 participants)")
                continue
            X, names = lmm_design(data)
            try:
                if np.linalg.matrix_rank(X) < X.shape[1]:
                    raise ValueError("a condition x group cell has no trials")
                fit = fit_random_intercept(
                    X, data["value"].to_numpy(float), data["participant"].to_numpy()
                )
            except (np.linalg.LinAlgError, ValueError) as exc:
                notes.append(f"{task}/{measure}: mixed model could not be fitted: {exc}")
                continue
            if fit.singular:
                notes.append(
                    f"{task}/{measure}: mixed model warning: singular fit, the participant "
                    f"intercept SD is {fit.theta:.2g} of the residual SD (below lme4's "
                    f"isSingular tolerance {SINGULAR_TOL:g})"
                )
            z = fit.beta / fit.se
            p_values = 2 * stats.norm.sf(np.abs(z))
            for term, est, se, p_value in zip(names, fit.beta, fit.se, p_values, strict=True):
                rows.append(
                    {
                        "task": task,
                        "measure": measure,
                        "term": term,
                        "estimate": float(est),
                        "se": float(se),
                        "p": float(p_value),
                        "p_method": "Wald z",
                    }
                )
    columns = ["task", "measure", "term", "estimate", "se", "p", "p_method"]
    return pd.DataFrame(rows, columns=columns), notes


def _missing_questionnaires(trials: pd.DataFrame, long: pd.DataFrame) -> list[str]:
    notes = []
    tlx = long[long["measure"].str.startswith("tlx_")]
    for task, g in trials.groupby("task", sort=False):
        answered = set(tlx.loc[tlx["task"] == task, "participant"])
        missing = sorted(set(g["participant"]) - answered)
        if missing:
            notes.append(f"{task}/tlx_*: excluded {', '.join(missing)} (no questionnaires)")
    return notes


def analyze(
    trials: pd.DataFrame,
    long: pd.DataFrame,
    ss_type: int = DEFAULT_SS_TYPE,
    withdrawn: Sequence[str] = (),
) -> Analysis:
    """The study's analysis: descriptives, condition tests, mixed ANOVA, mixed model.

    Parameters
    ----------
    trials
        One row per measured trial (`study.analysis.frames`).
    long
        The participant means, one row per participant, task, measure and condition.
    ss_type
        Sums-of-squares type of the mixed ANOVA (2 or 3).
    withdrawn
        The exclusion notes of participants already left out
        (`frames.without_withdrawn`).

    Returns
    -------
    Analysis
        The tables, the exclusions and notes, and the data source (simulated or
        measured trials).
    """
    comparisons, excluded = compare_conditions(long)
    excluded = [*withdrawn, *_missing_questionnaires(trials, long), *excluded]
    anova, anova_notes = mixed_anova(long, ss_type=ss_type)
    lmm, lmm_notes = mixed_model(trials)
    return Analysis(
        descriptives=descriptives(long),
        comparisons=comparisons,
        mixed_anova=anova,
        lmm=lmm,
        exclusions=excluded,
        warnings=anova_notes + lmm_notes,
        source=DataSource.of(trials),
        ss_type=ss_type,
    )
