"""Tidy frames from the study database (long format in, tidy out; pingouin's manner).

- `trial_frame`: one row per measured trial (completed, not practice, the latest attempt
  of each slot): participant, group, task, condition, trial, completion_time_s, the
  measures of every task in the frame under their own names (`study.protocol.tasks`:
  peak_proximal_force_n and peak_distal_force_n for LCCA, peak_force_demanded_n and
  peak_tip_force_n for NOTES, ...; empty for another task's rows), success, driver
  (simulated, keyboard, hardware or imported: `study.analysis.source` labels every
  output by it).
- `tlx_frame`: one row per questionnaire: participant, group, task, condition,
  tlx_raw, tlx_weighted (empty without the pairwise comparisons), tlx_mental ...
- `participant_means`: long format, one row per participant x task x condition x measure
  (the mean over that block's trials; TLX values as they are): the unit of analysis.
"""

from __future__ import annotations

import pandas as pd
from sqlalchemy import Engine

from db.models.tlx import TLX_SUBSCALES
from study.protocol.trial_table import TRIAL_KEYS, measure_columns, trial_frame

__all__ = [
    "TLX_MEASURES",
    "TRIAL_KEYS",
    "measure_columns",
    "participant_means",
    "tlx_frame",
    "trial_frame",
    "trial_measures",
    "without_withdrawn",
]

TLX_MEASURES = ("tlx_raw", "tlx_weighted", *(f"tlx_{s}" for s in TLX_SUBSCALES))


def trial_measures(trials: pd.DataFrame) -> list[str]:
    """The analysed measure columns of the tasks in `trials`."""
    return measure_columns(trials["task"].unique().tolist(), analysed_only=True)


def tlx_frame(engine: Engine) -> pd.DataFrame:
    from study.protocol.tlx import scored_tlx

    out = [
        {
            "participant": r["participant"],
            "group": r["group"],
            "task": r["task"],
            "condition": r["condition"],
            "tlx_raw": r["tlx_raw"],
            "tlx_weighted": float("nan") if r["tlx_weighted"] is None else r["tlx_weighted"],
            **{f"tlx_{s}": float(r[s]) for s in TLX_SUBSCALES},
        }
        for r in scored_tlx(engine)
    ]
    return pd.DataFrame(out, columns=["participant", "group", "task", "condition", *TLX_MEASURES])


def without_withdrawn(
    engine: Engine, trials: pd.DataFrame, tlx: pd.DataFrame
) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """The frames without withdrawn participants, and one exclusion note per task and
    withdrawn participant who had data in it (their data stay in the database); one
    withdrawn before any data is listed too, so every withdrawal is accounted for. The
    trials marked invalid (`study.protocol.corrections.mark_trial`) are left out as
    well, each listed with its reason."""
    from study.protocol.withdrawal import withdrawn_participants

    withdrawn = withdrawn_participants(engine)
    notes: list[str] = []
    for frame in (trials, tlx):
        gone = frame[frame["participant"].isin(list(withdrawn))]
        for task, code in gone[["task", "participant"]].drop_duplicates().itertuples(index=False):
            note = f"{task}/all measures: excluded {code} (withdrawn: {withdrawn[code]})"
            if note not in notes:
                notes.append(note)
    with_data = set(trials["participant"]) | set(tlx["participant"])
    for code, reason in withdrawn.items():
        if code not in with_data:
            notes.append(f"all tasks: excluded {code} (withdrawn: {reason}; no data stored)")
    keep_trials = trials[~trials["participant"].isin(list(withdrawn))]
    keep_tlx = tlx[~tlx["participant"].isin(list(withdrawn))]
    keep_trials, invalid = _without_invalid(engine, keep_trials)
    return keep_trials.reset_index(drop=True), keep_tlx.reset_index(drop=True), notes + invalid


def _without_invalid(engine: Engine, trials: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """`trials` without the trials marked invalid, and one exclusion note per trial."""
    from study.protocol.corrections import invalid_trials

    invalid = invalid_trials(engine)
    if not invalid or not len(trials):
        return trials, []
    columns = (trials[c] for c in ("participant", "task", "condition", "trial"))
    keys = [(str(p), str(t), str(c), int(n)) for p, t, c, n in zip(*columns, strict=True)]
    drop = [key in invalid for key in keys]
    notes = [
        f"{task}/all measures: excluded {code} {condition} trial {n} "
        f"(marked invalid: {invalid[(code, task, condition, n)]})"
        for (code, task, condition, n), d in zip(keys, drop, strict=True)
        if d
    ]
    return trials[[not d for d in drop]].reset_index(drop=True), notes


def participant_means(trials: pd.DataFrame, tlx: pd.DataFrame) -> pd.DataFrame:
    """Long format: participant, group, task, condition, measure, value."""
    keys = ["participant", "group", "task", "condition"]
    parts = []
    if len(trials):
        means = trials.groupby(keys, as_index=False)[trial_measures(trials)].mean()
        parts.append(means.melt(id_vars=keys, var_name="measure", value_name="value"))
    if len(tlx):
        parts.append(
            tlx[keys + list(TLX_MEASURES)].melt(
                id_vars=keys, var_name="measure", value_name="value"
            )
        )
    if not parts:
        return pd.DataFrame(columns=[*keys, "measure", "value"])
    return pd.concat(parts, ignore_index=True).dropna(subset=["value"])
