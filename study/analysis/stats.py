"""The study's statistics on participant means ([endovascular], IV-D).

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
  pingouin for it would slow `study analyze`'s start; statsmodels' `multipletests`
  gives the same values but runs a garbage collection on every call).
- `mixed_anova`: group (between) x condition (within) with partial eta squared and
  Type II (default) or Type III sums of squares, equal to R's afex `aov_ez(type = 2|3)`.
  pingouin's `mixed_anova` has Type II only, so both come from two one-way models in
  closed form (`anova.py` says how); unequal group sizes are stated.
- `mixed_model` (`study.analysis.mixed_model`): a linear mixed model over all trials,
  value ~ condition * group with a random intercept per participant, REML at lme4's
  optimum, t tests with Satterthwaite df (lmerTest) or Kenward-Roger's, and the
  condition effect as marginal means over the groups (emmeans). A singular fit (lme4's
  `isSingular`) is noted with the table.
- `design_checks` (`study.analysis.crossover`): the crossover's period, carry-over and
  trial-position effects, added to the model where the data call for them.

Participants without both conditions of a comparison are excluded from it, and each
exclusion is stated.

Each analysis runs on rows: participant means as `Long` tuples and trials as dicts
(`descriptive_rows`, `comparison_rows`, `mixed_anova_rows`, `mixed_model_rows`,
`analyze_rows`), which is what `study analyze` calls, so that it loads no pandas; the
functions above take and return pandas frames around them. The distributions and the
Shapiro-Wilk and Wilcoxon p-values are `study.analysis.distributions` (no scipy).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from study.analysis.anova import anova_rows
from study.analysis.distributions import (
    rank_average,
    shapiro_wilk,
    signed_rank_exact_p,
    signed_rank_normal_p,
    t_ppf,
    t_two_sided,
)
from study.analysis.mixed_model import DEFAULT_DDF, LMM_COLUMNS, mixed_model_rows
from study.analysis.source import DRIVERS, DataSource
from study.errors import StudyInputError

if TYPE_CHECKING:  # the command's path builds no frame: pandas only for the frame API
    import pandas as pd

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
DESCRIPTIVE_COLUMNS = (
    "task",
    "measure",
    "group",
    "condition",
    "n",
    "mean",
    "sd",
    "median",
    "iqr",
    "ci_low",
    "ci_high",
)
LONG_COLUMNS = ("participant", "group", "task", "condition", "measure", "value")
"""The participant means (`frames.participant_means`): one row per participant x task x
condition x measure."""
Row = dict[str, Any]
Long = list[tuple[Any, ...]]
"""Participant means as tuples in the order of `LONG_COLUMNS`."""


def frame(rows: list[Row], columns: Sequence[str]) -> pd.DataFrame:
    """Rows as a pandas frame (pandas imported here: the frame API's cost only).

    Parameters
    ----------
    rows : list of dict of str to Any
        The table's rows, each a column name -> value mapping.
    columns : Sequence of str
        The frame's columns, in order (a row's key not among them is dropped).

    Returns
    -------
    pandas.DataFrame
        One row per element of `rows`, with exactly `columns`.
    """
    import pandas as pd

    return pd.DataFrame(rows, columns=list(columns))


def long_records(long: pd.DataFrame) -> Long:
    """A frame of participant means as `Long` tuples.

    Parameters
    ----------
    long : pandas.DataFrame
        The participant means, with at least the columns `LONG_COLUMNS`.

    Returns
    -------
    Long
        One tuple per row, its values in the order of `LONG_COLUMNS`.
    """
    return list(long[list(LONG_COLUMNS)].itertuples(index=False, name=None))


def _groups(items: Iterable[tuple[Any, Any]]) -> dict[Any, list[Any]]:
    """key -> values, keys in order of first appearance (pandas' `groupby(sort=False)`)."""
    out: dict[Any, list[Any]] = {}
    for key, value in items:
        out.setdefault(key, []).append(value)
    return out


def _finite(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and math.isnan(value))


@dataclass
class Analysis:
    """The study's analysis: its four tables, notes and data source (`analyze` returns it).

    Attributes
    ----------
    descriptive_rows, comparison_rows, anova_rows, lmm_rows : list of dict of str to Any
        The tables as rows; the `descriptives`, `comparisons`, `mixed_anova` and `lmm`
        properties give them as pandas frames (`DESCRIPTIVE_COLUMNS`,
        `COMPARISON_COLUMNS`, `ANOVA_COLUMNS`, `LMM_COLUMNS`).
    exclusions : list of str
        Who or what was left out of which test, and why (one line each).
    warnings : list of str
        Notes of the ANOVA and the mixed model (skipped fits, unequal groups, boundary).
    source : DataSource
        The analysed trials by driver.
    """

    descriptive_rows: list[Row]
    comparison_rows: list[Row]
    anova_rows: list[Row]
    lmm_rows: list[Row]
    exclusions: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    source: DataSource = field(default_factory=lambda: DataSource(dict.fromkeys(DRIVERS, 0)))
    """The analysed trials by driver; every output says when they are simulated."""
    ss_type: int = 2
    """Sums-of-squares type of the mixed ANOVA."""
    ddf: str = DEFAULT_DDF
    """Degrees of freedom of the mixed model's t tests (Satterthwaite or Kenward-Roger)."""
    design_checks: list[Row] = field(default_factory=list)
    """The crossover's checks (`crossover.CHECK_COLUMNS`), one per task, measure, effect."""
    design_fit: list[Row] = field(default_factory=list)
    """The model before and after the checks (`crossover.FIT_COLUMNS`)."""

    @cached_property
    def descriptives(self) -> pd.DataFrame:
        """The descriptive statistics as a frame.

        Returns
        -------
        pandas.DataFrame
            `descriptive_rows` under `DESCRIPTIVE_COLUMNS`.
        """
        return frame(self.descriptive_rows, DESCRIPTIVE_COLUMNS)

    @cached_property
    def comparisons(self) -> pd.DataFrame:
        """The VO against HV tests as a frame.

        Returns
        -------
        pandas.DataFrame
            `comparison_rows` under `COMPARISON_COLUMNS`.
        """
        return frame(self.comparison_rows, COMPARISON_COLUMNS)

    @cached_property
    def mixed_anova(self) -> pd.DataFrame:
        """The mixed ANOVA table as a frame.

        Returns
        -------
        pandas.DataFrame
            `anova_rows` under `ANOVA_COLUMNS`.
        """
        return frame(self.anova_rows, ANOVA_COLUMNS)

    @cached_property
    def lmm(self) -> pd.DataFrame:
        """The linear mixed model's fixed effects as a frame.

        Returns
        -------
        pandas.DataFrame
            `lmm_rows` under `LMM_COLUMNS`.
        """
        return frame(self.lmm_rows, LMM_COLUMNS)

    @property
    def tasks(self) -> list[str]:
        """The tasks the analysis has rows of.

        Returns
        -------
        list of str
            Task names, in order of first appearance across the four tables.
        """
        tables = (self.descriptive_rows, self.comparison_rows, self.anova_rows, self.lmm_rows)
        return list(dict.fromkeys(r["task"] for rows in tables for r in rows))

    def warnings_about(self, kind: str) -> list[str]:
        """The notes of one analysis.

        Parameters
        ----------
        kind : str
            The analysis as the notes name it: ``"mixed ANOVA"`` or ``"mixed model"``.

        Returns
        -------
        list of str
            The `warnings` that mention `kind`, in order.
        """
        return [w for w in self.warnings if kind in w]

    def for_task(self, task: str) -> Analysis:
        """The same analysis restricted to one task.

        Parameters
        ----------
        task : str
            A task's name (``"lcca"``).

        Returns
        -------
        Analysis
            The task's rows of the four tables, its notes and exclusions; the same
            `source` and `ss_type`.
        """

        def keep(rows: list[Row]) -> list[Row]:
            return [r for r in rows if r["task"] == task]

        return Analysis(
            descriptive_rows=keep(self.descriptive_rows),
            comparison_rows=keep(self.comparison_rows),
            anova_rows=keep(self.anova_rows),
            lmm_rows=keep(self.lmm_rows),
            exclusions=[e for e in self.exclusions if e.startswith(f"{task}/")],
            warnings=[w for w in self.warnings if w.startswith(f"{task}/")],
            source=self.source,
            ss_type=self.ss_type,
            ddf=self.ddf,
            design_checks=keep(self.design_checks),
            design_fit=keep(self.design_fit),
        )


def descriptives(long: pd.DataFrame) -> pd.DataFrame:
    """Descriptive statistics of the participant means.

    Parameters
    ----------
    long : pandas.DataFrame
        One row per participant, task, measure and condition: columns task, measure,
        group, condition, participant, value.

    Returns
    -------
    pandas.DataFrame
        Per task, measure, group and condition: n, mean, sd, median, iqr and the
        t-based 95 % interval of the mean (ci_low, ci_high); NaN where n = 1.
    """
    return frame(descriptive_rows(long_records(long)), DESCRIPTIVE_COLUMNS)


def descriptive_rows(long: Long) -> list[Row]:
    """`descriptives` on `Long` tuples.

    Parameters
    ----------
    long : Long
        The participant means as tuples in the order of `LONG_COLUMNS`.

    Returns
    -------
    list of dict of str to Any
        One row per task, measure, group and condition (in order of first
        appearance), keyed by `DESCRIPTIVE_COLUMNS`; sd and the interval are NaN
        where n = 1.
    """
    rows = []
    cells = _groups(((t, m, g, c), v) for _, g, t, c, m, v in long)
    for (task, measure, group, condition), values in cells.items():
        x = np.array(values, dtype=float)
        n = len(x)
        mean = float(np.mean(x))
        sd = float(np.std(x, ddof=1)) if n > 1 else float("nan")
        half = float(t_ppf(0.975, n - 1) * sd / math.sqrt(n)) if n > 1 else float("nan")
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
    return rows


def hedges_g_av(vo: np.ndarray, hv: np.ndarray) -> float:
    """Hedges' g_av of paired samples [lakens2013].

    Parameters
    ----------
    vo, hv : numpy.ndarray
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


def paired_t(b: np.ndarray, a: np.ndarray) -> float:
    """The paired t statistic of b - a (scipy's `ttest_rel`).

    Parameters
    ----------
    b, a : numpy.ndarray
        The two samples, paired by position, in the measure's unit.

    Returns
    -------
    float
        The mean difference over its standard error; infinite or NaN when the
        differences have no spread.
    """
    d = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.mean(d) / np.sqrt(np.var(d, ddof=1) / len(d)))


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
    """`diff` with rounding noise removed.

    Values within `RESOLUTION_REL` x `scale` of zero become 0, and runs of |values| that
    close become one value (the run's first), so that ties and zeros are those of the
    data's resolution.

    Parameters
    ----------
    diff : numpy.ndarray
        Differences of paired values, in the measure's unit.
    scale : float or None, optional
        The magnitude of the data the differences came from, in the same unit;
        None: the largest |diff|.

    Returns
    -------
    numpy.ndarray
        A new float array of `diff`'s shape, signs kept.

    Examples
    --------
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
    vo, hv : numpy.ndarray
        The participants' values in the two conditions, paired by position.

    Returns
    -------
    float
        (R+ - R-) / total over the ranks of the non-zero differences, taken at the
        data's resolution (`at_resolution`); 0 when every difference is zero.
    """
    d = at_resolution(hv - vo, _magnitude(vo, hv))
    d = d[d != 0]
    ranks = rank_average(np.abs(d))
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
    diff : numpy.ndarray
        The paired differences (HV - VO).
    scale : float or None, optional
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
    ranks = rank_average(np.abs(d))
    v = float(ranks[d > 0].sum())
    p = signed_rank_exact_p(v, len(d)) if exact else signed_rank_normal_p(ranks, v)
    return v, p, method


def compare_conditions(
    long: pd.DataFrame, a: str = "VO", b: str = "HV"
) -> tuple[pd.DataFrame, list[str]]:
    """Condition `b` against `a` per task, measure and group, on participant means.

    A paired t test with Hedges' g_av where the differences pass Shapiro-Wilk at
    `ALPHA`, else the Wilcoxon signed-rank test with the rank-biserial correlation; the
    p-values of the groups of one task and measure are Holm-adjusted together.

    Parameters
    ----------
    long : pandas.DataFrame
        One row per participant, task, measure and condition (columns task, measure,
        group, condition, participant, value).
    a : str, optional
        The baseline condition.
    b : str, optional
        The condition compared against `a`.

    Returns
    -------
    tuple of (pandas.DataFrame, list of str)
        The tests (`COMPARISON_COLUMNS`) and notes: participants left out of a test for
        lacking one of the conditions, and tests skipped for too few pairs.
    """
    rows, excluded = comparison_rows(long_records(long), a, b)
    return frame(rows, COMPARISON_COLUMNS), excluded


def _pairs(long: Long, a: str, b: str) -> dict[tuple[Any, ...], dict[Any, dict[str, float]]]:
    """(task, measure, group) -> participant -> condition -> mean value (duplicates
    averaged, as a pivot table does), in order of first appearance."""
    cells: dict[tuple[Any, ...], dict[Any, dict[str, list[float]]]] = {}
    for participant, group, task, condition, measure, value in long:
        block = cells.setdefault((task, measure, group), {}).setdefault(participant, {})
        if _finite(value):
            block.setdefault(condition, []).append(float(value))
    return {
        key: {p: {c: float(np.mean(v)) for c, v in conds.items()} for p, conds in people.items()}
        for key, people in cells.items()
    }


def comparison_rows(long: Long, a: str = "VO", b: str = "HV") -> tuple[list[Row], list[str]]:
    """`compare_conditions` on `Long` tuples.

    Parameters
    ----------
    long : Long
        The participant means as tuples in the order of `LONG_COLUMNS`.
    a : str, optional
        The baseline condition.
    b : str, optional
        The condition compared against `a`.

    Returns
    -------
    rows : list of dict of str to Any
        One row per task, measure and group with at least three complete pairs, keyed
        by `COMPARISON_COLUMNS`.
    excluded : list of str
        One line per exclusion (participants missing a condition, too few pairs).
    """
    rows, excluded = [], []
    for (task, measure, group), people in _pairs(long, a, b).items():
        label = f"{task}/{measure}/{group}"
        complete, missing_note = _complete_pairs(people, a, b, label)
        excluded += missing_note
        n = len(complete)
        if n < 3:
            excluded.append(f"{label}: n = {n} pairs, too few to test")
            continue
        vo = np.array([c[a] for c in complete])
        hv = np.array([c[b] for c in complete])
        row: Row = {"task": task, "measure": measure, "group": group, "n": n}
        row.update(_paired_test(vo, hv))
        rows.append({c: row.get(c, float("nan")) for c in COMPARISON_COLUMNS})
    _holm_within_families(rows)
    return rows, excluded


def _complete_pairs(
    people: dict[Any, dict[str, float]], a: str, b: str, label: str
) -> tuple[list[dict[str, float]], list[str]]:
    """The condition means of the participants with both `a` and `b`, and the note
    (none or one) naming those without one of them."""
    people = {p: c for p, c in people.items() if c}  # a pivot drops all-empty rows
    missing = [p for p, c in people.items() if a not in c or b not in c]
    complete = [c for c in people.values() if a in c and b in c]
    if not missing:
        return complete, []
    return complete, [f"{label}: excluded {', '.join(map(str, missing))} (missing {a} or {b})"]


def _paired_test(vo: np.ndarray, hv: np.ndarray) -> Row:
    """Both conditions' means and SDs, Shapiro-Wilk on the differences, and the test it
    picks: the paired t-test with Hedges' g_av, or the Wilcoxon signed-rank test with
    the rank-biserial correlation."""
    diff = hv - vo
    normal_p = shapiro_wilk(diff)[1] if np.ptp(diff) > 0 else 1.0
    row: Row = {
        "mean_vo": float(vo.mean()),
        "mean_hv": float(hv.mean()),
        "sd_vo": float(vo.std(ddof=1)),
        "sd_hv": float(hv.std(ddof=1)),
        "shapiro_p": normal_p,
    }
    if normal_p >= ALPHA:
        t = paired_t(hv, vo)
        row.update(
            test="paired_t",
            statistic=t,
            p=t_two_sided(t, len(vo) - 1),
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
    return row


def _holm_within_families(rows: list[Row]) -> None:
    """Set each row's `p_holm`: Holm's correction across the groups of one task x measure."""
    families = _groups(((r["task"], r["measure"]), r) for r in rows)
    for family in families.values():
        for r, adjusted in zip(family, holm(np.array([r["p"] for r in family])), strict=True):
            r["p_holm"] = float(adjusted)


def _sizes(counts: dict[Any, int]) -> str:
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
    long : pandas.DataFrame
        One row per participant, task, measure and condition (columns task, measure,
        group, condition, participant, value).
    a : str, optional
        The first level of the within factor.
    b : str, optional
        The second level of the within factor.
    ss_type : int, optional
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
    rows, notes = mixed_anova_rows(long_records(long), a, b, ss_type)
    return frame(rows, ANOVA_COLUMNS), notes


def mixed_anova_rows(
    long: Long, a: str = "VO", b: str = "HV", ss_type: int = DEFAULT_SS_TYPE
) -> tuple[list[Row], list[str]]:
    """`mixed_anova` on `Long` tuples.

    Parameters
    ----------
    long : Long
        The participant means as tuples in the order of `LONG_COLUMNS`.
    a : str, optional
        The first level of the within factor.
    b : str, optional
        The second level of the within factor.
    ss_type : int, optional
        Sums-of-squares type, 2 or 3 (`DEFAULT_SS_TYPE` says why 2 by default).

    Returns
    -------
    rows : list of dict of str to Any
        The ANOVA terms of each task x measure, keyed by `ANOVA_COLUMNS`.
    notes : list of str
        One line per skipped fit or unequal group sizes.

    Raises
    ------
    StudyInputError
        `ss_type` is neither 2 nor 3.
    """
    if ss_type not in SS_TYPES:
        raise StudyInputError(f"sums-of-squares type {ss_type!r}; expected 2 or 3")
    rows, notes = [], []
    for (task, measure), people in _condition_values(long, a, b).items():
        anova, cell_notes = _anova_of(f"{task}/{measure}", _wide(people, a, b), ss_type)
        notes += cell_notes
        for row in anova:
            rows.append({"task": task, "measure": measure, **row})
    return rows, notes


def _condition_values(
    long: Long, a: str, b: str
) -> dict[tuple[Any, Any], dict[tuple[Any, Any], dict[str, list[float]]]]:
    """(task, measure) -> (participant, group) -> condition -> its finite values, for the
    conditions `a` and `b`, in order of first appearance."""
    measures: dict[tuple[Any, Any], dict[tuple[Any, Any], dict[str, list[float]]]] = {}
    for participant, group, task, condition, measure, value in long:
        if condition in (a, b) and _finite(value):
            people = measures.setdefault((task, measure), {})
            people.setdefault((participant, group), {}).setdefault(condition, []).append(value)
    return measures


def _wide(
    people: dict[tuple[Any, Any], dict[str, list[float]]], a: str, b: str
) -> list[tuple[Any, float, float]]:
    """(group, mean of `a`, mean of `b`) of each participant with both conditions."""
    # one participant per row, sorted by participant (a pivot table's order)
    return [
        (group, float(np.mean(c[a])), float(np.mean(c[b])))
        for (_, group), c in sorted(people.items(), key=lambda item: item[0])
        if a in c and b in c
    ]


def _anova_of(
    label: str, wide: list[tuple[Any, float, float]], ss_type: int
) -> tuple[list[Row], list[str]]:
    """The mixed ANOVA of one task x measure (`wide`: `_wide`), or none when a group has
    fewer than two participants or no group varies; and the notes saying so, or that the
    groups are unequal."""
    sizes: dict[Any, int] = {}
    for group, _, _ in wide:
        sizes[group] = sizes.get(group, 0) + 1
    if len(sizes) < 2 or min(sizes.values()) < 2:
        return [], [f"{label}: mixed ANOVA skipped (groups {_sizes(sizes)})"]
    notes = []
    if len(set(sizes.values())) > 1:
        notes.append(
            f"{label}: mixed ANOVA on unequal group sizes {_sizes(sizes)}, "
            f"Type {'II' if ss_type == 2 else 'III'} sums of squares"
        )
    group = np.array([g for g, _, _ in wide], dtype=object)
    va = np.array([x for _, x, _ in wide])
    vb = np.array([y for _, _, y in wide])
    if all(np.var(v[group == g], ddof=1) == 0 for g in sizes for v in (va, vb)):
        notes.append(f"{label}: mixed ANOVA skipped (no variance within groups)")
        return [], notes
    return anova_rows(group, va, vb, ss_type), notes


def _missing_questionnaires(trials: list[Row], long: Long) -> list[str]:
    notes = []
    answered: dict[Any, set[Any]] = {}
    for participant, _, task, _, measure, _ in long:
        if str(measure).startswith("tlx_"):
            answered.setdefault(task, set()).add(participant)
    for task, people in _groups((t["task"], t["participant"]) for t in trials).items():
        missing = sorted(set(people) - answered.get(task, set()))
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
    trials : pandas.DataFrame
        The measured trials (`frames.trial_frame`).
    long : pandas.DataFrame
        The participant means (`frames.participant_means`).
    ss_type : int, optional
        Sums of squares of the mixed ANOVA, 2 or 3.
    withdrawn : Sequence of str, optional
        Exclusion notes of what was already left out (`frames.without_withdrawn`).

    Returns
    -------
    Analysis
        The tables, the exclusions and warnings, and the data source.

    Raises
    ------
    StudyInputError
        `ss_type` is neither 2 nor 3, or a trial names a task that is not known.
    """
    return analyze_rows(trials.to_dict("records"), long_records(long), ss_type, withdrawn)


def _design_checks(trials: list[Row]) -> Any:
    """The crossover's checks (`crossover.design_checks`) when the trials carry their
    block; none (and a note) when they do not."""
    from study.analysis.crossover import CrossoverResult, design_checks

    if not trials or not all("block" in t or "period" in t for t in trials):
        return CrossoverResult(
            notes=["design checks skipped: the trials carry no block order"] if trials else []
        )
    return design_checks(trials)


def analyze_rows(
    trials: list[Row],
    long: Long,
    ss_type: int = DEFAULT_SS_TYPE,
    withdrawn: Sequence[str] = (),
    ddf: str = DEFAULT_DDF,
) -> Analysis:
    """`analyze` on rows: what `study analyze` runs, without pandas.

    Parameters
    ----------
    trials : list of dict of str to Any
        The measured trials (`study.protocol.study_rows.trial_rows`).
    long : Long
        The participant means (`frames.participant_mean_rows`).
    ss_type : int, optional
        Sums-of-squares type of the mixed ANOVA, 2 or 3.
    withdrawn : Sequence of str, optional
        Exclusion lines for withdrawn participants, stated first.
    ddf : str, optional
        The mixed model's df: Satterthwaite (default) or Kenward-Roger.

    Returns
    -------
    Analysis
        The four tables, the exclusions and the notes.

    Raises
    ------
    StudyInputError
        `ss_type` is neither 2 nor 3, or a trial names a task that is not known.
    """
    comparisons, excluded = comparison_rows(long)
    excluded = [*withdrawn, *_missing_questionnaires(trials, long), *excluded]
    anova, anova_notes = mixed_anova_rows(long, ss_type=ss_type)
    lmm, lmm_notes = mixed_model_rows(trials, ddf=ddf)
    checks = _design_checks(trials)
    return Analysis(
        descriptive_rows=descriptive_rows(long),
        comparison_rows=comparisons,
        anova_rows=anova,
        lmm_rows=lmm,
        exclusions=excluded,
        warnings=anova_notes + lmm_notes + checks.notes,
        source=DataSource.of_drivers([t["driver"] for t in trials if "driver" in t]),
        ss_type=ss_type,
        ddf=ddf,
        design_checks=checks.checks,
        design_fit=checks.fits,
    )
