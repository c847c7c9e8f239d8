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

from collections.abc import Iterable

import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.tlx import TLX_SUBSCALES
from db.models.trial import Trial
from study.protocol.tasks import COMPLETION_TIME, get_task

TLX_MEASURES = ("tlx_raw", "tlx_weighted", *(f"tlx_{s}" for s in TLX_SUBSCALES))
TRIAL_KEYS = ("participant", "group", "task", "condition", "trial")


def measure_columns(tasks: Iterable[str], analysed_only: bool = False) -> list[str]:
    """The measure columns of `tasks`' trials, in the tasks' order, each once."""
    out: list[str] = []
    for name in tasks:
        task = get_task(name)
        for m in task.all_measures:
            if m.name not in out and (m.analysed or not analysed_only):
                out.append(m.name)
    return out


def trial_frame(engine: Engine, tasks: Iterable[str] = ()) -> pd.DataFrame:
    """The measured trials; the measure columns of `tasks` and of every task with trials."""
    with Session(engine) as session:
        rows = session.execute(
            select(Participant.code, Participant.group, Trial)
            .join(Trial, Trial.participant_id == Participant.id)
            .where(Trial.status == "completed", Trial.practice.is_(False))
            .order_by(Participant.code, Trial.block_index, Trial.trial_index, Trial.attempt)
        ).all()
        latest = {}
        for code, group, t in rows:
            latest[(code, t.task, t.condition, t.trial_index)] = {
                "participant": code,
                "group": group,
                "task": t.task,
                "condition": t.condition,
                "trial": t.trial_index + 1,
                COMPLETION_TIME: t.completion_time_s,
                **t.measure_values,
                "success": bool(t.success),
                "driver": t.driver,
            }
    names = list(dict.fromkeys([*tasks, *(r["task"] for r in latest.values())]))
    columns = [*TRIAL_KEYS, *measure_columns(names), "success", "driver"]
    return pd.DataFrame(list(latest.values()), columns=columns)


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
    withdrawn before any data is listed too, so every withdrawal is accounted for."""
    from study.protocol.withdrawal import withdrawn_participants

    withdrawn = withdrawn_participants(engine)
    if not withdrawn:
        return trials, tlx, []
    notes = []
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
    return keep_trials.reset_index(drop=True), keep_tlx.reset_index(drop=True), notes


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
