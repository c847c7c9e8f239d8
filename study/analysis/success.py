"""Task success, VO against HV within each group: the exact McNemar test.

A participant succeeded in a condition when every measured trial of that block
succeeded (one trial per block: that trial's outcome). The pairs that differ carry the
test: b participants succeeded in VO only, c in HV only; the exact McNemar p is the
two-sided binomial test of b against b + c at 1/2 (statsmodels'
`mcnemar(exact=True)`, R's `binom.test(b, b + c)`). With no discordant pair there is
nothing to test (p = 1, as both give). Holm's correction runs across the groups of a
task, as for the other measures.
"""

from __future__ import annotations

from typing import Any

import numpy as np

SUCCESS_COLUMNS = (
    "task",
    "group",
    "n",
    "success_vo",
    "success_hv",
    "vo_only",
    "hv_only",
    "p",
    "p_holm",
    "p_method",
)
Row = dict[str, Any]


def _blocks(trials: list[Row]) -> dict[tuple[Any, Any], dict[Any, dict[str, bool]]]:
    """(task, group) -> participant -> condition -> every trial succeeded."""
    out: dict[tuple[Any, Any], dict[Any, dict[str, bool]]] = {}
    for t in trials:
        if t.get("success") is None:
            continue
        people = out.setdefault((t["task"], t["group"]), {})
        conditions = people.setdefault(t["participant"], {})
        key = t["condition"]
        conditions[key] = conditions.get(key, True) and bool(t["success"])
    return out


def success_rows(trials: list[Row], a: str = "VO", b: str = "HV") -> tuple[list[Row], list[str]]:
    """The exact McNemar test of success per task and group.

    Parameters
    ----------
    trials : list of dict of str to Any
        The measured trials: participant, group, task, condition, success.
    a, b : str, optional
        The two conditions.

    Returns
    -------
    rows : list of dict of str to Any
        One row per task and group with at least one complete pair (`SUCCESS_COLUMNS`):
        the participants who succeeded in each condition, the discordant pairs, p.
    excluded : list of str
        One line per participant left out (one condition missing).
    """
    # lazy: statsmodels.stats.contingency_tables costs 1.1 s at start-up
    from statsmodels.stats.contingency_tables import mcnemar

    # lazy: study.analysis.comparisons costs 8 ms at start-up
    from study.analysis.comparisons import holm

    rows, excluded = [], []
    for (task, group), people in _blocks(trials).items():
        missing = [p for p, c in people.items() if a not in c or b not in c]
        if missing:
            excluded.append(
                f"{task}/success/{group}: excluded {', '.join(map(str, missing))} "
                "(one condition missing)"
            )
        pairs = [(c[a], c[b]) for c in people.values() if a in c and b in c]
        if pairs:
            rows.append({"task": task, "group": group, **_mcnemar(pairs, mcnemar)})
    for task in dict.fromkeys(r["task"] for r in rows):
        family = [r for r in rows if r["task"] == task]
        for r, adjusted in zip(family, holm(np.array([r["p"] for r in family])), strict=True):
            r["p_holm"] = float(adjusted)
    return rows, excluded


def _mcnemar(pairs: list[tuple[bool, bool]], mcnemar: Any) -> Row:
    """The counts and the exact McNemar p of (VO success, HV success) pairs."""
    vo_only = sum(x and not y for x, y in pairs)
    hv_only = sum(y and not x for x, y in pairs)
    both = sum(x and y for x, y in pairs)
    table = [[both, vo_only], [hv_only, len(pairs) - both - vo_only - hv_only]]
    p = float(mcnemar(table, exact=True).pvalue) if vo_only + hv_only else 1.0
    return {
        "n": len(pairs),
        "success_vo": both + vo_only,
        "success_hv": both + hv_only,
        "vo_only": vo_only,
        "hv_only": hv_only,
        "p": p,
        "p_method": "exact (binomial)",
    }
