"""The crossover's own effects on the measured people: period, carry-over and trial
position, looked for in the mixed model's residual and added where the data call for
them (Grizzle 1965; Jones and Kenward, Design and Analysis of Cross-Over Trials; Senn,
Cross-over Trials in Clinical Research).

Tidy in, tidy out: `design_checks` takes one row per trial (participant, group, task,
condition, trial, and block or period) and returns one row per task, measure and
effect, plus one row per task and measure on the model before and after
(`CrossoverResult`). It needs no study database.

The base model is the analysis' own (`mixed_model`): value ~ condition * group +
(1 | participant), REML, with Satterthwaite df. Each participant's blocks of a task are
its periods (1, 2, ...) in the order they were run; the participant's condition order
is the condition of the first period. Each check is the t test (Satterthwaite df) of a
term added to the base model, in the model the crossover literature tests it in
(Grizzle's two stages; Jones and Kenward, ch. 2):

- `period`: the second block minus the first (practice or fatigue between blocks),
  in base + period (+ trial position), that is within participants and assuming no
  carry-over. In a two-period crossover it is the within-participant interaction of
  condition and condition order: half the sum of the second-minus-first differences of
  the two orders. A differential carry-over, if there is one, adds half of itself to
  it (in two periods no within-participant contrast separates the two).
- `carry_over`: the differential carry-over, VO after HV minus HV after VO (the
  one-direction term "VO in a later block than HV", whose coefficient with the period in
  the model is that difference), in base + period + carry-over (+ trial position). In
  two periods it is aliased with the condition order, so it is estimated between
  participants only (from the participants' totals, Grizzle's test), which is why it
  costs the condition effect its within-participant precision once added.
- `trial_position`: the slope per trial over the trial's place within its block
  (centred within the block, so orthogonal to the block-level terms), in the period's
  model, when a block has several trials.

Not testable (and then not reported, with a note): a period or carry-over when every
participant of the task had the same condition order (they are then aliased with the
condition), a trial position when no block has two trials.

All the checks of a study are one family, Holm-corrected (pingouin's
`multicomp(method="holm")`, as the comparisons), so that a study without these effects
has a term added in at most `ALPHA` of studies; a check with p_holm below `ALPHA` is
added to the model of its task and measure (a carry-over with the period beside it,
which defines it), and the HV - VO marginal contrast (averaged over the groups, as
emmeans) is reported before and after, with the residual and participant SDs. Where a
carry-over is added, the first-period comparison is reported too: HV against VO in the
first block only, between participants (value ~ condition + group + (1 | participant)),
the estimate the crossover literature falls back on when carry-over is present.

A singular fit (the participant SD estimated at zero, lme4's `isSingular`) pools the
between-participant residual into sigma, and a between-participant spread smaller than
the within-participant one is why the fit is singular: the pooled sigma is then too
small for a within-participant term, whose t is too large (at one trial a block and no
true participant spread, 6-7 % of such checks fell below .05 against 5 %). So at a
singular fit the period and the trial position are tested against the
within-participant residual alone (participants as fixed effects, statsmodels' OLS),
as the classical crossover analysis does (Jones and Kenward, ch. 2); at an interior fit
that is the mixed model's own test. The carry-over, between participants, keeps the
mixed model's test (the pooled sigma is larger than its own error there: conservative).

A model is fitted once per task and measure and set of terms (`_Cell.fit`); the base
model is the one `mixed_model` fits, which `stats_lmm.fit_random_intercept` returns
from its cache.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from study.analysis.mixed_model import (
    lmm_design,
    marginal_weights,
    reference_condition,
)
from study.analysis.stats_lmm import SINGULAR_TOL, Contrast, Fit, fit_random_intercept

if TYPE_CHECKING:
    import pandas as pd

Row = dict[str, Any]
ALPHA = 0.05
"""Family-wise error rate of the checks (Holm)."""
EFFECTS = ("period", "carry_over", "trial_position")
CHECK_COLUMNS = (
    "task",
    "measure",
    "effect",
    "estimate",
    "ci",
    "p",
    "p_holm",
    "added",
    "condition_before",
    "condition_after",
)
"""`analysis.json`'s `design_checks` entries: exactly these keys."""
FIT_COLUMNS = ("task", "measure", "added", "fit_before", "fit_after", "first_period")
"""`analysis.json`'s `design_fit` entries: the model before and after, per task x measure."""


@dataclass
class CrossoverResult:
    """The checks (`CHECK_COLUMNS`), the fits before and after (`FIT_COLUMNS`), notes."""

    checks: list[Row] = field(default_factory=list)
    fits: list[Row] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_frames(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        # lazy: pandas costs 0.3 s at start-up
        import pandas as pd

        return (
            pd.DataFrame(self.checks, columns=list(CHECK_COLUMNS)),
            pd.DataFrame(self.fits, columns=list(FIT_COLUMNS)),
        )


def _finite(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and np.isnan(value))


def with_periods(trials: list[Row]) -> list[Row]:
    """`trials` with `period` (the block's place among the participant's blocks of its
    task, from 1) and `order` (the condition of the participant's first block of the
    task); rows that already carry `period` keep it."""
    blocks: dict[tuple[Any, Any], dict[Any, Any]] = {}
    for t in trials:
        if "period" not in t:
            blocks.setdefault((t["participant"], t["task"]), {})[t["block"]] = t["condition"]
    rank = {key: {b: i + 1 for i, b in enumerate(sorted(bs))} for key, bs in blocks.items()}
    out = [
        {
            **t,
            "period": t["period"]
            if "period" in t
            else rank[(t["participant"], t["task"])][t["block"]],
        }
        for t in trials
    ]
    first: dict[tuple[Any, Any], tuple[Any, Any]] = {}
    for t in out:
        key = (t["participant"], t["task"])
        if key not in first or t["period"] < first[key][0]:
            first[key] = (t["period"], t["condition"])
    return [{**t, "order": first[(t["participant"], t["task"])][1]} for t in out]


@dataclass(frozen=True)
class _Cell:
    """One task x measure: its trials as arrays and the base design."""

    X: np.ndarray
    names: list[str]
    y: np.ndarray
    participant: np.ndarray
    condition: np.ndarray
    period: np.ndarray
    position: np.ndarray
    conditions: list[Any]
    groups: list[Any]
    group: np.ndarray
    fits: dict[tuple[str, ...], tuple[Fit, list[str]]] = field(default_factory=dict)
    """The models fitted so far, by their added terms (in `EFFECTS` order)."""

    @classmethod
    def of(cls, data: list[Row], measure: str) -> _Cell:
        X, names = lmm_design({k: [t[k] for t in data] for k in ("condition", "group")})
        condition = np.array([t["condition"] for t in data], dtype=object)
        ref = reference_condition(condition)
        return cls(
            X=X,
            names=names,
            y=np.array([t[measure] for t in data], float),
            participant=np.array([t["participant"] for t in data], dtype=object),
            condition=condition,
            period=np.array([t["period"] for t in data], float),
            position=np.array([t["trial"] for t in data], float),
            conditions=[ref, *sorted(set(condition) - {ref})],
            groups=sorted({t["group"] for t in data}),
            group=np.array([t["group"] for t in data], dtype=object),
        )

    def column(self, effect: str) -> np.ndarray | None:
        """The effect's design column, or None when it is not testable here."""
        if effect == "trial_position":
            if self.position.max(initial=0) < 2:
                return None
            keys = list(zip(self.participant, self.period, strict=True))
            mean: dict[Any, list[float]] = {}
            for k, x in zip(keys, self.position, strict=True):
                mean.setdefault(k, []).append(x)
            return self.position - np.array([np.mean(mean[k]) for k in keys])
        later = (self.period > 1).astype(float)
        if effect == "period":
            column = later
        else:  # VO in a later block than HV
            column = later * (self.condition == self.conditions[0])
        full = (
            np.column_stack([self.X, later, column])
            if effect != "period"
            else np.column_stack([self.X, column])
        )
        if np.linalg.matrix_rank(full) < full.shape[1]:
            return None
        return column


def _condition(fit: Fit, names: list[str], cell: _Cell) -> dict[str, Any]:
    """The HV - VO marginal contrast of `fit` (the extra terms weighted 0)."""
    w = marginal_weights(cell.names, cell.conditions, cell.groups)
    L = np.zeros(len(names))
    L[: len(cell.names)] = w[cell.conditions[1]] - w[cell.conditions[0]]
    c = fit.contrast(L)
    return _summary(c)


def _summary(c: Contrast) -> dict[str, Any]:
    return {"estimate": c.estimate, "ci": [c.ci_low, c.ci_high], "p": c.p, "df": c.df}


def _fit_summary(fit: Fit) -> dict[str, Any]:
    return {
        "residual_sd": fit.sigma,
        "participant_sd": fit.theta * fit.sigma,
        "reml_criterion": fit.reml_crit,
    }


def _design(cell: _Cell, terms: tuple[str, ...]) -> np.ndarray:
    """The base design of `cell` with the columns of `terms`."""
    columns = []
    for e in terms:
        column = cell.column(e)
        if column is None:  # pragma: no cover - the effects are the testable ones
            raise ValueError(f"effect {e!r} is not testable in this cell")
        columns.append(column)
    return np.column_stack([cell.X, *columns]) if terms else cell.X


def _fit(cell: _Cell, effects: list[str]) -> tuple[Fit, list[str]]:
    """The base model of `cell` plus `effects`, fitted once per set of terms."""
    terms = tuple(e for e in EFFECTS if e in effects)
    if terms not in cell.fits:
        cell.fits[terms] = (
            fit_random_intercept(_design(cell, terms), cell.y, cell.participant),
            [*cell.names, *terms],
        )
    return cell.fits[terms]


def _within_participants(cell: _Cell, effects: list[str], effect: str) -> Contrast:
    """The t test of `effect` against the within-participant residual: y on one
    intercept per participant and the columns of the model that vary within a
    participant (statsmodels' OLS; the columns constant within every participant are
    the intercepts' span)."""
    from statsmodels.regression.linear_model import OLS

    terms = tuple(e for e in EFFECTS if e in effects)
    X = _design(cell, terms)
    people, index = np.unique(cell.participant.astype(str), return_inverse=True)
    means = np.zeros((len(people), X.shape[1]))
    np.add.at(means, index, X)
    means /= np.bincount(index)[:, None]
    varies = np.abs(X - means[index]).max(axis=0) > 1e-12
    dummies = (index[:, None] == np.arange(len(people))[None, :]).astype(float)
    names = [*cell.names, *terms]
    kept = [n for n, v in zip(names, varies, strict=True) if v]
    design = np.column_stack([dummies, X[:, varies]])
    fit = OLS(cell.y, design).fit()
    L = np.zeros(design.shape[1])
    L[len(people) + kept.index(effect)] = 1.0
    test = fit.t_test(L)
    return Contrast.of(
        float(np.ravel(test.effect)[0]), float(np.ravel(test.sd)[0]), float(fit.df_resid)
    )


def _test_model(effect: str, testable: list[str]) -> list[str]:
    """The terms of the model `effect` is tested in (module docstring): the period and
    the trial position without the carry-over, the carry-over beside both."""
    if effect == "carry_over":
        return testable
    return [e for e in testable if e != "carry_over"]


def _first_period(cell: _Cell) -> dict[str, Any] | None:
    """HV against VO in the first block only, between participants."""
    keep = cell.period == 1
    condition, group = cell.condition[keep], cell.group[keep]
    hv = (condition != cell.conditions[0]).astype(float)
    groups = sorted(set(group))
    X = np.column_stack(
        [np.ones(keep.sum()), hv, *[(group == g).astype(float) for g in groups[1:]]]
    )
    if len(set(condition)) < 2 or np.linalg.matrix_rank(X) < X.shape[1]:
        return None
    fit = fit_random_intercept(X, cell.y[keep], cell.participant[keep])
    return {
        **_summary(fit.contrast(np.eye(X.shape[1])[1])),
        "participants": len(set(cell.participant[keep])),
    }


def _holm(p: list[float]) -> list[float]:
    if not p:
        return []
    # the comparisons' Holm (pingouin's): statsmodels' runs a full garbage collection
    # on every call, a tenth of the command's time
    from study.analysis.comparisons import holm

    return [float(x) for x in holm(np.array(p, dtype=float))]


def design_checks(
    trials: pd.DataFrame | list[Row], measures: tuple[str, ...] | None = None
) -> CrossoverResult:
    """The period, carry-over and trial-position checks of every task and measure.

    Parameters
    ----------
    trials : pandas.DataFrame or list of dict
        One row per measured trial: participant, group, task, condition, trial (its
        number within the block, from 1), block (any increasing number in the order the
        participant's blocks were run) or period (from 1), and the measures by name.
    measures : tuple of str or None, optional
        The measures to check; None: each task's analysed measures.

    Returns
    -------
    CrossoverResult
        `checks`: one row per task, measure and effect (`CHECK_COLUMNS`: estimate,
        ci as [low, high], p, p_holm, added, and the HV - VO marginal contrast before
        and after as {estimate, ci, p, df}); `fits`: one row per task and measure
        (`FIT_COLUMNS`: the effects added, the residual and participant SDs and REML
        criterion before and after, the first-period comparison where a carry-over is
        added); `notes`: the checks that could not be made, and why.
    """
    # lazy: study.protocol.tasks costs 7 ms at start-up
    from study.protocol.tasks import get_task

    rows = trials if isinstance(trials, list) else trials.to_dict("records")
    rows = with_periods(rows)
    result = CrossoverResult()
    cells: dict[tuple[Any, Any], tuple[_Cell, Fit]] = {}
    tasks: dict[Any, list[Row]] = {}
    for t in rows:
        tasks.setdefault(t["task"], []).append(t)
    for task, task_rows in tasks.items():
        for measure in measures or get_task(task).analysed_measures:
            data = [t for t in task_rows if _finite(t.get(measure))]
            _check_cell(task, measure, data, result, cells)
    _decide(result, cells)
    return result


def _check_cell(
    task: Any,
    measure: str,
    data: list[Row],
    result: CrossoverResult,
    cells: dict[tuple[Any, Any], tuple[_Cell, Fit]],
) -> None:
    """Fit the base model and the model with every testable check; record the checks."""
    label = f"{task}/{measure}"
    if len({t["participant"] for t in data}) < 3:
        result.notes.append(f"{label}: design checks skipped (fewer than 3 participants)")
        return
    cell = _Cell.of(data, measure)
    try:
        if np.linalg.matrix_rank(cell.X) < cell.X.shape[1]:
            raise ValueError("a condition x group cell has no trials")
        base, _ = _fit(cell, [])
        testable = [e for e in EFFECTS if cell.column(e) is not None]
    except (np.linalg.LinAlgError, ValueError) as exc:
        result.notes.append(f"{label}: design checks could not be fitted: {exc}")
        return
    cells[(task, measure)] = (cell, base)
    for effect in EFFECTS:
        if effect not in testable:
            if effect != "trial_position" or cell.position.max(initial=0) >= 2:
                result.notes.append(
                    f"{label}: {effect} not testable "
                    "(every participant had the same condition order)"
                )
            continue
        try:
            fit, names = _fit(cell, _test_model(effect, testable))
        except (np.linalg.LinAlgError, ValueError) as exc:
            result.notes.append(f"{label}: {effect} could not be fitted: {exc}")
            continue
        if effect != "carry_over" and fit.theta < SINGULAR_TOL:
            c = _within_participants(cell, _test_model(effect, testable), effect)
        else:
            c = fit.contrast(np.eye(len(names))[names.index(effect)])
        result.checks.append(
            {
                "task": task,
                "measure": measure,
                "effect": effect,
                "estimate": c.estimate,
                "ci": [c.ci_low, c.ci_high],
                "p": c.p,
            }
        )


def _decide(result: CrossoverResult, cells: dict[tuple[Any, Any], tuple[_Cell, Fit]]) -> None:
    """Holm over every check; the model after, per task and measure, with what it added."""
    tested = [r for r in result.checks if np.isfinite(r["p"])]
    for row in result.checks:
        row["p_holm"], row["added"] = float("nan"), False
    for row, adjusted in zip(tested, _holm([r["p"] for r in tested]), strict=True):
        row["p_holm"] = adjusted
        row["added"] = bool(adjusted < ALPHA)
    for (task, measure), (cell, base) in cells.items():
        mine = [r for r in result.checks if (r["task"], r["measure"]) == (task, measure)]
        chosen = {r["effect"] for r in mine if r["added"]}
        if "carry_over" in chosen:
            chosen.add("period")  # the carry-over term is defined beside the period
        added = [e for e in EFFECTS if e in chosen]
        before = _condition(base, cell.names, cell)
        after_fit, names = _fit(cell, added)
        after = _condition(after_fit, names, cell)
        for r in mine:
            r["condition_before"], r["condition_after"] = before, after
        result.fits.append(
            {
                "task": task,
                "measure": measure,
                "added": added,
                "fit_before": _fit_summary(base),
                "fit_after": _fit_summary(after_fit),
                "first_period": _first_period(cell) if "carry_over" in added else None,
            }
        )
