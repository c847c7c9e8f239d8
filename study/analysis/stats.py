"""The study's statistics on participant means ([endovascular], IV-D).

- `descriptives`: per task, measure, group and condition: n, mean, SD, median, IQR and
  the t-based 95 % confidence interval of the mean.
- `compare_conditions` (`study.analysis.comparisons`): VO against HV within each group
  on paired participant means, decided on the differences at the data's resolution.
  Shapiro-Wilk (scipy.stats) picks a paired t-test (mean difference and Cohen's d_z with
  their 95 % CIs, Hedges' g_av with the n - 1 correction, TOST against the design's
  bounds, the JZS Bayes factor of pingouin) or the signed-rank test with its exact
  conditional p below 50 pairs (`signed_rank`); constant differences get no t statistic
  and all-zero differences are not testable. Holm's correction runs across the groups of
  one task x measure, and each row names its family.
- `mixed_anova`: group (between) x condition (within) with partial eta squared and
  Type II (default) or Type III sums of squares, equal to R's afex `aov_ez(type = 2|3)`.
  pingouin's `mixed_anova` has Type II only, so both come from two one-way models
  fitted by statsmodels' OLS and its nested F tests (`anova.py` says how); unequal group
  sizes are stated, and a term whose model fits exactly is not testable.
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
`analyze_rows`), which is what `study analyze` calls; the functions above take and
return pandas frames around them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from study.analysis.anova import anova_rows
from study.analysis.comparisons import (
    COMPARISON_COLUMNS,
    comparison_rows,
)
from study.analysis.mixed_model import DEFAULT_DDF, LMM_COLUMNS, mixed_model_rows
from study.analysis.paired import EquivalenceBounds
from study.analysis.source import DRIVERS, DataSource
from study.analysis.success import success_rows
from study.errors import StudyInputError

if TYPE_CHECKING:  # the command's path builds no frame: pandas only for the frame API
    import pandas as pd

ALPHA = 0.05
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
    # lazy: pandas costs 0.3 s at start-up
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
    success_rows: list[Row] = field(default_factory=list)
    """The exact McNemar test of success per task and group (`success.SUCCESS_COLUMNS`)."""
    bounds: EquivalenceBounds = field(default_factory=EquivalenceBounds)
    """The TOST bounds the comparisons used."""
    task_sources: dict[str, DataSource] = field(default_factory=dict)
    """Each task's analysed trials by driver."""
    forces_by_source: dict[str, int] = field(default_factory=dict)
    """The analysed trials by where their forces came from (`study_rows.forces_source`:
    measured, simulated, unknown)."""
    ends: dict[str, int] = field(default_factory=dict)
    """The analysed physical-phantom trials by who ended them (`study_rows.trial_end`:
    button, experimenter, time_limit)."""

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
            The task's rows of the tables, its notes and exclusions (and those of every
            task), its own trials' `source`; the same `ss_type` and `bounds`.
        """

        def keep(rows: list[Row]) -> list[Row]:
            return [r for r in rows if r["task"] == task]

        def mine(notes: list[str]) -> list[str]:
            return [e for e in notes if e.startswith((f"{task}/", "all tasks"))]

        return Analysis(
            descriptive_rows=keep(self.descriptive_rows),
            comparison_rows=keep(self.comparison_rows),
            anova_rows=keep(self.anova_rows),
            lmm_rows=keep(self.lmm_rows),
            exclusions=mine(self.exclusions),
            warnings=[w for w in self.warnings if w.startswith(f"{task}/")],
            source=self.task_sources.get(task, self.source),
            ss_type=self.ss_type,
            ddf=self.ddf,
            design_checks=keep(self.design_checks),
            design_fit=keep(self.design_fit),
            success_rows=keep(self.success_rows),
            bounds=self.bounds,
            task_sources={task: self.task_sources[task]} if task in self.task_sources else {},
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
    # lazy: scipy.stats costs 0.7 s at start-up
    from scipy.stats import t as t_dist

    rows = []
    cells = _groups(((t, m, g, c), v) for _, g, t, c, m, v in long)
    for (task, measure, group, condition), values in cells.items():
        x = np.array(values, dtype=float)
        n = len(x)
        mean = float(np.mean(x))
        sd = float(np.std(x, ddof=1)) if n > 1 else float("nan")
        half = float(t_dist.ppf(0.975, n - 1) * sd / math.sqrt(n)) if n > 1 else float("nan")
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
    rows = anova_rows(group, va, vb, ss_type)
    exact = [r["source"] for r in rows if r.pop("exact_fit")]
    if "group" in exact:
        notes.append(
            f"{label}: mixed ANOVA group not testable (the participants' means do not "
            "vary within groups)"
        )
    if "condition" in exact:
        notes.append(
            f"{label}: mixed ANOVA condition and interaction not testable (the HV - VO "
            "differences do not vary within groups)"
        )
    return rows, notes


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
    bounds: EquivalenceBounds | None = None,
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
    bounds : EquivalenceBounds or None, optional
        The TOST bounds of the comparisons (None: no TOST).

    Returns
    -------
    Analysis
        The tables, the exclusions and warnings, and the data source.

    Raises
    ------
    StudyInputError
        `ss_type` is neither 2 nor 3, or a trial names a task that is not known.
    """
    return analyze_rows(
        trials.to_dict("records"), long_records(long), ss_type, withdrawn, bounds=bounds
    )


def _design_checks(trials: list[Row]) -> Any:
    """The crossover's checks (`crossover.design_checks`) when the trials carry their
    block; none (and a note) when they do not."""
    # lazy: study.analysis.crossover costs 4 ms at start-up
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
    bounds: EquivalenceBounds | None = None,
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
        Exclusion lines of what was left out before (withdrawn participants, invalid
        trials, questionnaires without pairwise choices), stated first.
    ddf : str, optional
        The mixed model's df: Satterthwaite (default) or Kenward-Roger.
    bounds : EquivalenceBounds or None, optional
        The TOST bounds of the comparisons (None: no TOST).

    Returns
    -------
    Analysis
        The four tables, the exclusions and the notes.

    Raises
    ------
    StudyInputError
        `ss_type` is neither 2 nor 3, or a trial names a task that is not known.
    """

    comparisons, excluded = comparison_rows(long, bounds=bounds)
    excluded = [*withdrawn, *_missing_questionnaires(trials, long), *excluded]
    anova, anova_notes = mixed_anova_rows(long, ss_type=ss_type)
    lmm, lmm_notes = mixed_model_rows(trials, ddf=ddf)
    checks = _design_checks(trials)
    success, success_notes = success_rows(trials)
    excluded += success_notes
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
        success_rows=success,
        bounds=bounds or EquivalenceBounds(),
        task_sources={
            task: DataSource.of_drivers([t["driver"] for t in rows if "driver" in t])
            for task, rows in _groups((t["task"], t) for t in trials).items()
        },
        forces_by_source=_forces_by_source(trials),
        ends=_count(t.get("end") for t in trials),
    )


def _count(values: Iterable[str | None]) -> dict[str, int]:
    """How often each value other than None occurs, in the order first seen."""
    counts: dict[str, int] = {}
    for v in values:
        if v is not None:
            counts[v] = counts.get(v, 0) + 1
    return counts


def _forces_by_source(trials: list[dict[str, Any]]) -> dict[str, int]:
    """How many trials' forces were measured, simulated or of unknown source."""
    counts: dict[str, int] = {}
    for t in trials:
        if "forces" in t:
            counts[t["forces"]] = counts.get(t["forces"], 0) + 1
    return counts
