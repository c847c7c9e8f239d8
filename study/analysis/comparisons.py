"""VO against HV within each group, on participant means: the comparisons table.

`compare_conditions` takes a tidy frame (one row per subject x condition, as pingouin's
functions do; `task` and `measure` columns are optional), so data from any study can be
analysed without a study database. Each group's comparison is `paired.paired_comparison`;
Holm's correction runs across the testable groups of one task x measure, and every row
names the family it was corrected in (`holm_family`): a group that is not testable
(every difference zero) is no member, and says so. `comparison_rows` is the same on
`Long` tuples, what `study analyze` runs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from study.analysis.paired import EquivalenceBounds, paired_comparison

if TYPE_CHECKING:
    import pandas as pd

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
    "df",
    "mean_diff",
    "diff_ci_low",
    "diff_ci_high",
    "dz",
    "dz_ci_low",
    "dz_ci_high",
    "g_av",
    "tost_bound",
    "tost_p",
    "bf10",
    "constant_diff",
    "not_testable",
    "holm_family",
)
MIN_PAIRS = 3
"""The fewest complete pairs a group is tested with."""
Row = dict[str, Any]
Long = list[tuple[Any, ...]]


def compare_conditions(
    long: pd.DataFrame,
    a: str = "VO",
    b: str = "HV",
    *,
    dv: str = "value",
    within: str = "condition",
    subject: str = "participant",
    between: str = "group",
    bounds: EquivalenceBounds | None = None,
) -> tuple[pd.DataFrame, list[str]]:
    """Condition `b` against `a` per task, measure and group, on participant means.

    Parameters
    ----------
    long : pandas.DataFrame
        Tidy data: one row per subject and condition (per task and measure when the
        frame has `task` and `measure` columns); several rows of one subject and
        condition are averaged.
    a, b : str, optional
        The baseline condition and the condition compared against it (b - a).
    dv, within, subject, between : str, optional
        The columns of the value, the condition, the subject and the group (pingouin's
        names).
    bounds : EquivalenceBounds or None, optional
        The TOST bounds (None: no TOST).

    Returns
    -------
    tuple of (pandas.DataFrame, list of str)
        The tests (`COMPARISON_COLUMNS`) and the exclusions: subjects left out of a test
        for lacking one of the conditions, and groups with fewer than `MIN_PAIRS` pairs.
    """
    # lazy: pandas costs 0.3 s at start-up
    import pandas as pd

    columns = {subject: "participant", between: "group", within: "condition", dv: "value"}
    data = long.rename(columns=columns)
    for column, default in (("task", "-"), ("measure", dv)):
        if column not in data:
            data = data.assign(**{column: default})
    if between not in long:
        data = data.assign(group="all")
    keys = ["participant", "group", "task", "condition", "measure", "value"]
    records = list(data[keys].itertuples(index=False, name=None))
    rows, excluded = comparison_rows(records, a, b, bounds)
    return pd.DataFrame(rows, columns=list(COMPARISON_COLUMNS)), excluded


def _finite(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and np.isnan(value))


def _pairs(long: Long) -> dict[tuple[Any, ...], dict[Any, dict[str, float]]]:
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


def comparison_rows(
    long: Long, a: str = "VO", b: str = "HV", bounds: EquivalenceBounds | None = None
) -> tuple[list[Row], list[str]]:
    """`compare_conditions` on `Long` tuples.

    Parameters
    ----------
    long : Long
        The participant means as (participant, group, task, condition, measure, value).
    a, b : str, optional
        The baseline condition and the condition compared against it.
    bounds : EquivalenceBounds or None, optional
        The TOST bounds (None: no TOST).

    Returns
    -------
    rows : list of dict of str to Any
        One row per task, measure and group with at least `MIN_PAIRS` complete pairs,
        keyed by `COMPARISON_COLUMNS`.
    excluded : list of str
        One line per exclusion (participants missing a condition, too few pairs).
    """
    rows, excluded = [], []
    for (task, measure, group), people in _pairs(long).items():
        label = f"{task}/{measure}/{group}"
        complete, missing_note = _complete_pairs(people, a, b, label)
        excluded += missing_note
        n = len(complete)
        if n < MIN_PAIRS:
            excluded.append(f"{label}: n = {n} pairs, too few to test")
            continue
        vo = np.array([c[a] for c in complete])
        hv = np.array([c[b] for c in complete])
        bound = bounds.bound(str(measure), float(vo.mean())) if bounds else None
        row: Row = {"task": task, "measure": measure, "group": group, "n": n}
        row.update(paired_comparison(vo, hv, bound))
        rows.append({c: row.get(c, float("nan")) for c in COMPARISON_COLUMNS})
    holm_within_families(rows)
    return rows, excluded


def _complete_pairs(
    people: dict[Any, dict[str, float]], a: str, b: str, label: str
) -> tuple[list[dict[str, float]], list[str]]:
    """The condition means of the participants with both `a` and `b`, and the note
    (none or one) naming those without one of them, and which one they lack."""
    people = {p: c for p, c in people.items() if c}  # a pivot drops all-empty rows
    missing = [(p, a if a not in c else b) for p, c in people.items() if a not in c or b not in c]
    complete = [c for c in people.values() if a in c and b in c]
    if not missing:
        return complete, []
    who = ", ".join(f"{p} (one condition missing: no {lacking})" for p, lacking in missing)
    return complete, [f"{label}: excluded {who}"]


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values of one family; NaN stays NaN and is no member.

    Parameters
    ----------
    p : Float1D
        Unadjusted p-values, NaN for a test that could not be run.

    Returns
    -------
    Float1D
        Adjusted p-values, same order, at most 1 (pingouin's `multicomp(method="holm")`).

    >>> holm(np.array([0.01, np.nan, 0.04, 0.03])).tolist()
    [0.03, nan, 0.06, 0.06]
    """
    # lazy: pingouin costs 1.5 s at start-up
    import pingouin

    p = np.asarray(p, dtype=float)
    if not p.size:
        return p.copy()
    return np.asarray(pingouin.multicomp(p, method="holm")[1], dtype=float)


def holm_within_families(rows: list[Row]) -> None:
    """Set each row's `p_holm` and `holm_family`: Holm's correction across the testable
    groups of one task x measure (rows without a p are no member and get none)."""
    families: dict[tuple[Any, Any], list[Row]] = {}
    for r in rows:
        families.setdefault((r["task"], r["measure"]), []).append(r)
    for family in families.values():
        members = [r for r in family if _finite(r["p"])]
        named = ", ".join(str(r["group"]) for r in members)
        adjusted = holm(np.array([r["p"] for r in members])) if members else np.zeros(0)
        for r, p in zip(members, adjusted, strict=True):
            r["p_holm"] = float(p)
            r["holm_family"] = named
        for r in family:
            if not _finite(r["p"]):
                r["p_holm"] = float("nan")
                r["holm_family"] = f"not a member (of {named or 'none'})"
