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
- `mixed_model`: a linear mixed model over all trials, value ~ condition * group with a
  random intercept per participant, REML at the exact optimum (`stats_lmm`, equal to
  lme4); its p-values are Wald z tests (no Satterthwaite df; lmerTest's are a little
  larger on small samples). A singular fit (lme4's `isSingular`) is noted with the table.

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
from study.analysis.comparisons import (
    COMPARISON_COLUMNS,
    comparison_rows,
)
from study.analysis.paired import EquivalenceBounds
from study.analysis.source import DRIVERS, DataSource
from study.errors import StudyInputError

if TYPE_CHECKING:  # the command's path builds no frame: pandas only for the frame API
    import pandas as pd

ALPHA = 0.05
ANOVA_COLUMNS = ("task", "measure", "source", "F", "df1", "df2", "p", "np2", "ss_type")
LMM_COLUMNS = ("task", "measure", "term", "estimate", "se", "p", "p_method")
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
    success_rows: list[Row] = field(default_factory=list)
    """The exact McNemar test of success per task and group (`success.SUCCESS_COLUMNS`)."""
    bounds: EquivalenceBounds = field(default_factory=EquivalenceBounds)
    """The TOST bounds the comparisons used."""
    task_sources: dict[str, DataSource] = field(default_factory=dict)
    """Each task's analysed trials by driver."""

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
    return anova_rows(group, va, vb, ss_type), notes


CONDITION_TERM = "C(condition, Treatment('VO'))"


def lmm_design(data: Any) -> tuple[np.ndarray, list[str]]:
    """The fixed-effects design of value ~ condition * group.

    Treatment coding with VO and the alphabetically first group as reference.

    Parameters
    ----------
    data : Any
        Anything with ``data["condition"]`` and ``data["group"]`` (a frame's columns,
        arrays or lists), one entry per trial.

    Returns
    -------
    X : numpy.ndarray
        The design matrix, one row per trial: intercept, condition, group and
        condition x group indicator columns.
    names : list of str
        The columns' names as patsy names them (``Intercept``,
        ``C(condition, Treatment('VO'))[T.HV]``, ...).
    """
    condition = np.asarray(data["condition"], dtype=object)
    group_of = np.asarray(data["group"], dtype=object)
    conditions = [c for c in sorted(set(condition)) if c != "VO"]
    groups = sorted(set(group_of))[1:]
    cond = {c: (condition == c).astype(float) for c in conditions}
    grp = {g: (group_of == g).astype(float) for g in groups}
    columns, names = [np.ones(len(condition))], ["Intercept"]
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
    """The linear mixed model of every trial measure, per task.

    REML with a random intercept per participant (`stats_lmm`, lme4's optimum); p from
    Wald z tests.

    Parameters
    ----------
    trials : pandas.DataFrame
        One row per measured trial (participant, group, task, condition, measures).
    measures : tuple of str or None, optional
        The measures to model; default each task's analysed measures
        (`study.protocol.tasks`).

    Returns
    -------
    tuple of (pandas.DataFrame, list of str)
        The fixed effects (`LMM_COLUMNS`) and notes (skipped fits, a fit on the
        boundary as lme4's `isSingular` says).

    Raises
    ------
    StudyInputError
        A trial names a task that is not known (with `measures` None).
    """
    rows, notes = mixed_model_rows(trials.to_dict("records"), measures)
    return frame(rows, LMM_COLUMNS), notes


def mixed_model_rows(
    trials: list[Row], measures: tuple[str, ...] | None = None
) -> tuple[list[Row], list[str]]:
    """`mixed_model` on trial rows.

    Parameters
    ----------
    trials : list of dict of str to Any
        One row per measured trial: participant, group, task, condition and the
        measures by name.
    measures : tuple of str or None, optional
        The measures to model; None: each task's analysed measures
        (`study.protocol.tasks`).

    Returns
    -------
    rows : list of dict of str to Any
        The fixed effects of each task x measure, keyed by `LMM_COLUMNS`.
    notes : list of str
        One line per skipped or failed fit and per singular fit.

    Raises
    ------
    StudyInputError
        A trial names a task that is not known (with `measures` None).
    """
    from scipy.stats import norm

    from study.analysis.stats_lmm import SINGULAR_TOL, fit_random_intercept
    from study.protocol.tasks import get_task

    rows, notes = [], []
    keys = ("participant", "group", "condition")
    for task, g in _groups((t["task"], t) for t in trials).items():
        for measure in measures or get_task(task).analysed_measures:
            data = [t for t in g if _finite(t.get(measure)) and all(_finite(t[k]) for k in keys)]
            participants = np.array([t["participant"] for t in data], dtype=object)
            if len(set(participants)) < 3:
                notes.append(f"{task}/{measure}: mixed model skipped (fewer than 3 participants)")
                continue
            design = {k: [t[k] for t in data] for k in ("condition", "group")}
            X, names = lmm_design(design)
            try:
                if np.linalg.matrix_rank(X) < X.shape[1]:
                    raise ValueError("a condition x group cell has no trials")
                fit = fit_random_intercept(
                    X, np.array([t[measure] for t in data], dtype=float), participants
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
            for term, est, se in zip(names, fit.beta, fit.se, strict=True):
                rows.append(
                    {
                        "task": task,
                        "measure": measure,
                        "term": term,
                        "estimate": float(est),
                        "se": float(se),
                        "p": float(2 * norm.sf(abs(float(est / se)))),
                        "p_method": "Wald z",
                    }
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
    return analyze_rows(trials.to_dict("records"), long_records(long), ss_type, withdrawn, bounds)


def analyze_rows(
    trials: list[Row],
    long: Long,
    ss_type: int = DEFAULT_SS_TYPE,
    withdrawn: Sequence[str] = (),
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
    from study.analysis.success import success_rows

    comparisons, excluded = comparison_rows(long, bounds=bounds)
    excluded = [*withdrawn, *_missing_questionnaires(trials, long), *excluded]
    anova, anova_notes = mixed_anova_rows(long, ss_type=ss_type)
    lmm, lmm_notes = mixed_model_rows(trials)
    success, success_notes = success_rows(trials)
    excluded += success_notes
    return Analysis(
        descriptive_rows=descriptive_rows(long),
        comparison_rows=comparisons,
        anova_rows=anova,
        lmm_rows=lmm,
        exclusions=excluded,
        warnings=anova_notes + lmm_notes,
        source=DataSource.of_drivers([t["driver"] for t in trials if "driver" in t]),
        ss_type=ss_type,
        success_rows=success,
        bounds=bounds or EquivalenceBounds(),
        task_sources={
            task: DataSource.of_drivers([t["driver"] for t in rows if "driver" in t])
            for task, rows in _groups((t["task"], t) for t in trials).items()
        },
    )
