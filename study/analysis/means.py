"""The participant means, the unit of analysis, from the rows of `study.protocol.study_rows`
without pandas (`study analyze` builds no frame; `frames` builds its frames from these).

- `tlx_measure_rows`: a questionnaire row with its measures under their analysed names
  (tlx_raw, tlx_weighted (NaN without the pairwise comparisons), tlx_mental, ...).
- `participant_mean_rows`: `Long` tuples (participant, group, task, condition, measure,
  value): each block's mean over its trials of every analysed measure (blocks in sorted
  order, measure by measure), then the questionnaires' values as they are; no NaN.
- `without_withdrawn_rows`, `without_invalid_rows`, `restrict_rows`: the withdrawn
  participants, the trials marked invalid and `--driver`.
"""

from __future__ import annotations

import math
from typing import Any

from db.tlx_subscales import TLX_SUBSCALES
from study.analysis.source import DRIVERS, DataSource
from study.errors import StudyInputError
from study.protocol.study_rows import measure_columns

TLX_MEASURES = ("tlx_raw", "tlx_weighted", *(f"tlx_{s}" for s in TLX_SUBSCALES))
KEYS = ("participant", "group", "task", "condition")
Row = dict[str, Any]


def _finite(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def tlx_measure_rows(tlx: list[Row]) -> list[Row]:
    """`study_rows.tlx_rows` with the analysed names (the rows of `frames.tlx_frame`)."""
    return [
        {
            **{k: r[k] for k in KEYS},
            "tlx_raw": r["tlx_raw"],
            "tlx_weighted": float("nan") if r["tlx_weighted"] is None else r["tlx_weighted"],
            **{f"tlx_{s}": float(r[s]) for s in TLX_SUBSCALES},
        }
        for r in tlx
    ]


def participant_mean_rows(trials: list[Row], tlx: list[Row]) -> list[tuple[Any, ...]]:
    """The participant means of trial rows and `tlx_measure_rows` as `Long` tuples."""
    out: list[tuple[Any, ...]] = []
    if trials:
        tasks = list(dict.fromkeys(t["task"] for t in trials))
        blocks: dict[tuple[Any, ...], list[Row]] = {}
        for t in trials:
            blocks.setdefault(tuple(t[k] for k in KEYS), []).append(t)
        keys = sorted(blocks)
        for measure in measure_columns(tasks, analysed_only=True):
            for key in keys:
                values = [float(t[measure]) for t in blocks[key] if _finite(t.get(measure))]
                if values:
                    out.append((*key, measure, math.fsum(values) / len(values)))
    for measure in TLX_MEASURES:
        for r in tlx:
            if _finite(r[measure]):
                out.append((*(r[k] for k in KEYS), measure, float(r[measure])))
    return out


def withdrawal_notes(withdrawn: dict[str, str], trials: list[Row], tlx: list[Row]) -> list[str]:
    """One exclusion note per task and withdrawn participant who had data in it (their
    data stay in the database); one withdrawn before any data is listed too."""
    notes = []
    for rows in (trials, tlx):
        for r in rows:
            if r["participant"] in withdrawn:
                code = r["participant"]
                note = f"{r['task']}/all measures: excluded {code} (withdrawn: {withdrawn[code]})"
                if note not in notes:
                    notes.append(note)
    with_data = {r["participant"] for rows in (trials, tlx) for r in rows}
    for code, reason in withdrawn.items():
        if code not in with_data:
            notes.append(f"all tasks: excluded {code} (withdrawn: {reason}; no data stored)")
    return notes


def choiceless_notes(tlx: list[Row]) -> list[str]:
    """One exclusion note per questionnaire with ratings but no pairwise choices: it
    counts in the raw TLX and the subscales, not in the weighted TLX."""
    return [
        f"{r['task']}/tlx_weighted: excluded {r['participant']} {r['condition']} "
        "(questionnaire without pairwise choices; in the raw TLX and the subscales)"
        for r in tlx
        if r.get("tlx_weighted") is None
    ]


def without_withdrawn_rows(
    withdrawn: dict[str, str], trials: list[Row], tlx: list[Row]
) -> tuple[list[Row], list[Row], list[str]]:
    """The rows without withdrawn participants, and `withdrawal_notes`."""
    if not withdrawn:
        return trials, tlx, []
    notes = withdrawal_notes(withdrawn, trials, tlx)
    return (
        [r for r in trials if r["participant"] not in withdrawn],
        [r for r in tlx if r["participant"] not in withdrawn],
        notes,
    )


def without_invalid_rows(
    invalid: dict[tuple[str, str, str, int], str], trials: list[Row]
) -> tuple[list[Row], list[str]]:
    """The trial rows without those marked invalid (`study_rows.invalid_rows`), and one
    exclusion note per trial left out, with its reason (the trial stays stored)."""
    if not invalid:
        return trials, []
    kept, notes = [], []
    for r in trials:
        key = (r["participant"], r["task"], r["condition"], int(r["trial"]))
        if key in invalid:
            code, task, condition, n = key
            notes.append(
                f"{task}/all measures: excluded {code} {condition} trial {n} "
                f"(marked invalid: {invalid[key]})"
            )
        else:
            kept.append(r)
    return kept, notes


def restrict_rows(
    trials: list[Row], tlx: list[Row], driver: str | None
) -> tuple[list[Row], list[Row]]:
    """Only the trials of `driver` and the questionnaires of their blocks (None: all)."""
    if driver is None:
        return trials, tlx
    if driver not in DRIVERS:
        raise StudyInputError(f"driver {driver!r}; expected one of {', '.join(DRIVERS)}")
    kept = [t for t in trials if t["driver"] == driver]
    if not kept:
        present = DataSource.of_drivers([t["driver"] for t in trials]).trials_by_driver
        have = ", ".join(f"{d} ({n})" for d, n in present.items() if n) or "none stored"
        raise StudyInputError(f"no trials driven by {driver!r}; the database holds {have}")
    blocks = {(t["participant"], t["task"], t["condition"]) for t in kept}
    return kept, [r for r in tlx if (r["participant"], r["task"], r["condition"]) in blocks]
