"""The linear mixed model of every trial: value ~ condition * group + (1 | participant),
per task and measure, with small-sample t tests and the condition effect as marginal
means averaged over the groups.

Tidy in, tidy out (`mixed_model`: one row per trial in, one row per term out), so
trials of another study can be modelled without a study database. The fit and its
inference are `stats_lmm` (statsmodels' REML, polished to lme4's optimum; Satterthwaite
df as lmerTest, Kenward-Roger as pbkrtest). The rows are

- the fixed effects in treatment coding, reference levels condition VO and the first
  group in alphabetical order (R's default, so the coefficients are lme4's): the
  `HV` coefficient is the HV - VO difference in the reference group only;
- the marginal mean of each condition averaged over the groups with equal weights,
  and their HV - VO contrast (emmeans' `emmeans(fit, ~ condition)` and
  `pairs(..., reverse = TRUE)`): the condition effect of the whole sample, the row to
  read beside the ANOVA's condition effect.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from study.analysis.stats_lmm import DDF_METHODS, SINGULAR_TOL, fit_random_intercept
from study.errors import StudyInputError

if TYPE_CHECKING:
    import pandas as pd

    from study.analysis.stats_lmm import Fit

Row = dict[str, Any]
LMM_COLUMNS = (
    "task",
    "measure",
    "term",
    "estimate",
    "se",
    "p",
    "p_method",
    "kind",
    "df",
    "t",
    "ci_low",
    "ci_high",
    "reference",
)
"""The first seven as before the df were added; `kind` is coefficient, marginal mean or
marginal contrast; `reference` names the reference levels of the coefficients."""
DEFAULT_DDF = "Satterthwaite"
REFERENCE_CONDITION = "VO"
CONDITION_TERM = "C(condition, Treatment('VO'))"
"""The condition's coefficients' prefix with VO as reference (`condition_term`)."""
EQUAL = "groups weighted equally"
"""The marginal rows' `reference`: emmeans' default weights."""
KINDS = ("coefficient", "marginal mean", "marginal contrast")


def reference_condition(conditions: Iterable[Any]) -> Any:
    """VO when present, otherwise the alphabetically first condition."""
    levels = sorted(set(conditions))
    return REFERENCE_CONDITION if REFERENCE_CONDITION in levels else levels[0]


def condition_term(reference: Any = REFERENCE_CONDITION) -> str:
    return f"C(condition, Treatment('{reference}'))"


def lmm_design(data: Any) -> tuple[np.ndarray, list[str]]:
    """The fixed-effects design of value ~ condition * group.

    Treatment coding with VO (or, without VO, the alphabetically first condition) and
    the alphabetically first group as reference.

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
    ref = reference_condition(condition)
    term = condition_term(ref)
    conditions = [c for c in sorted(set(condition)) if c != ref]
    groups = sorted(set(group_of))[1:]
    cond = {c: (condition == c).astype(float) for c in conditions}
    grp = {g: (group_of == g).astype(float) for g in groups}
    columns, names = [np.ones(len(condition))], ["Intercept"]
    for c in conditions:
        columns.append(cond[c])
        names.append(f"{term}[T.{c}]")
    for g in groups:
        columns.append(grp[g])
        names.append(f"C(group)[T.{g}]")
    for g in groups:
        for c in conditions:
            columns.append(cond[c] * grp[g])
            names.append(f"{term}[T.{c}]:C(group)[T.{g}]")
    return np.column_stack(columns), names


def marginal_weights(
    names: list[str], conditions: list[Any], groups: list[Any]
) -> dict[Any, np.ndarray]:
    """condition -> the weights on the coefficients of its mean over the groups, each
    group weighted equally (emmeans' default `weights = "equal"`).

    Parameters
    ----------
    names : list of str
        The coefficients' names (`lmm_design`).
    conditions, groups : list
        Every level present, the reference first.

    Returns
    -------
    dict of condition to numpy.ndarray
        One weight vector per condition, shape (p,).
    """
    term = condition_term(conditions[0])
    out = {}
    for c in conditions:
        w = np.zeros(len(names))
        w[names.index("Intercept")] = 1.0
        for g in groups:
            # the cell mean of (c, g): intercept + group + condition + condition x group
            cells = [f"C(group)[T.{g}]"]
            if c != conditions[0]:
                cells += [f"{term}[T.{c}]", f"{term}[T.{c}]:C(group)[T.{g}]"]
            for name in cells:
                if name in names:
                    w[names.index(name)] += 1.0 / len(groups)
        out[c] = w
    return out


def mixed_model(
    trials: pd.DataFrame,
    measures: tuple[str, ...] | None = None,
    ddf: str = DEFAULT_DDF,
) -> tuple[pd.DataFrame, list[str]]:
    """The linear mixed model of every trial measure, per task.

    Parameters
    ----------
    trials : pandas.DataFrame
        One row per measured trial: participant, group, task, condition and the
        measures by name.
    measures : tuple of str or None, optional
        The measures to model; default each task's analysed measures
        (`study.protocol.tasks`).
    ddf : str, optional
        Degrees of freedom of the t tests: "Satterthwaite" (lmerTest's default) or
        "Kenward-Roger".

    Returns
    -------
    tuple of (pandas.DataFrame, list of str)
        One row per coefficient, marginal mean and marginal contrast (`LMM_COLUMNS`:
        task, measure, term, estimate, se, p, p_method, kind, df, t, ci_low, ci_high,
        reference) and notes (skipped fits, a fit on the boundary as lme4's
        `isSingular` says).

    Raises
    ------
    StudyInputError
        A trial names a task that is not known (with `measures` None), or `ddf` is
        not one of `stats_lmm.DDF_METHODS`.
    """
    # lazy: pandas costs 0.3 s at start-up
    import pandas as pd

    rows, notes = mixed_model_rows(trials.to_dict("records"), measures, ddf)
    return pd.DataFrame(rows, columns=list(LMM_COLUMNS)), notes


def _finite(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and np.isnan(value))


def _by_task(trials: Iterable[Row]) -> dict[Any, list[Row]]:
    out: dict[Any, list[Row]] = {}
    for t in trials:
        out.setdefault(t["task"], []).append(t)
    return out


def mixed_model_rows(
    trials: list[Row], measures: tuple[str, ...] | None = None, ddf: str = DEFAULT_DDF
) -> tuple[list[Row], list[str]]:
    """`mixed_model` on trial rows (what `study analyze` runs, without pandas).

    Parameters
    ----------
    trials : list of dict of str to Any
        One row per measured trial: participant, group, task, condition and the
        measures by name.
    measures : tuple of str or None, optional
        The measures to model; None: each task's analysed measures.
    ddf : str, optional
        "Satterthwaite" or "Kenward-Roger".

    Returns
    -------
    rows : list of dict of str to Any
        Keyed by `LMM_COLUMNS`.
    notes : list of str
        One line per skipped or failed fit and per singular fit.
    """
    # lazy: study.protocol.tasks costs 6 ms at start-up
    from study.protocol.tasks import get_task

    if ddf not in DDF_METHODS:
        raise StudyInputError(
            f"degrees-of-freedom method {ddf!r}; expected one of {', '.join(DDF_METHODS)}"
        )
    rows, notes = [], []
    keys = ("participant", "group", "condition")
    for task, g in _by_task(trials).items():
        for measure in measures or get_task(task).analysed_measures:
            data = [t for t in g if _finite(t.get(measure)) and all(_finite(t[k]) for k in keys)]
            label = f"{task}/{measure}"
            try:
                fitted = fit_condition_model(data, measure)
            except ValueError as exc:
                notes.append(f"{label}: mixed model {exc}")
                continue
            fit, names, conditions, groups = fitted
            if fit.singular:
                notes.append(
                    f"{label}: mixed model warning: singular fit, the participant "
                    f"intercept SD is {fit.theta:.2g} of the residual SD (below lme4's "
                    f"isSingular tolerance {SINGULAR_TOL:g})"
                )
            for row in model_rows(fit, names, conditions, groups, ddf):
                rows.append({"task": task, "measure": measure, **row})
    return rows, notes


def fit_condition_model(
    data: list[Row], measure: str
) -> tuple[Fit, list[str], list[str], list[str]]:
    """The REML fit of `measure` ~ condition * group + (1 | participant) on `data`.

    Returns
    -------
    tuple
        The fit, the coefficients' names, the conditions and the groups (reference first).

    Raises
    ------
    ValueError
        Fewer than 3 participants, an empty condition x group cell, or a failed fit
        (its message says which, worded to follow "mixed model").
    """
    participants = np.array([t["participant"] for t in data], dtype=object)
    if len(set(participants)) < 3:
        raise ValueError("skipped (fewer than 3 participants)")
    design = {k: [t[k] for t in data] for k in ("condition", "group")}
    X, names = lmm_design(design)
    if np.linalg.matrix_rank(X) < X.shape[1]:
        raise ValueError("could not be fitted: a condition x group cell has no trials")
    try:
        fit = fit_random_intercept(X, np.array([t[measure] for t in data], float), participants)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(f"could not be fitted: {exc}") from exc
    ref = reference_condition(design["condition"])
    conditions = [ref, *sorted(set(design["condition"]) - {ref})]
    return fit, names, conditions, sorted(set(design["group"]))


def model_rows(
    fit: Fit, names: list[str], conditions: list[str], groups: list[str], ddf: str
) -> list[Row]:
    """The coefficients, the marginal means and the marginal contrasts of one fit."""
    method = f"{ddf} t"
    reference = f"condition {conditions[0]}, group {groups[0]}"
    rows = []
    for i, term in enumerate(names):
        L = np.zeros(len(names))
        L[i] = 1.0
        rows.append(_row(term, "coefficient", fit.contrast(L, ddf), method, reference))
    weights = marginal_weights(names, conditions, groups)
    for c, w in weights.items():
        rows.append(_row(f"mean {c}", "marginal mean", fit.contrast(w, ddf), method, EQUAL))
    for c in conditions[1:]:
        L = weights[c] - weights[conditions[0]]
        contrast = fit.contrast(L, ddf)
        rows.append(_row(f"{c} - {conditions[0]}", "marginal contrast", contrast, method, EQUAL))
    return rows


def _row(term: str, kind: str, c: Any, method: str, reference: str) -> Row:
    p = None if kind == "marginal mean" else c.p  # a mean's test against 0 says nothing
    return {
        "term": term,
        "estimate": c.estimate,
        "se": c.se,
        "p": p,
        "p_method": method,
        "kind": kind,
        "df": c.df,
        "t": None if kind == "marginal mean" else c.t,
        "ci_low": c.ci_low,
        "ci_high": c.ci_high,
        "reference": reference,
    }
