"""Tidy frames from the study database (long format in, tidy out; pingouin's manner).

- `trial_frame`: one row per measured trial (completed, not practice, the latest attempt
  of each slot): participant, group, task, condition, trial, completion_time_s,
  peak_proximal_force_n, peak_distal_force_n, success, driver (simulated, keyboard,
  hardware or imported: `study.analysis.source` labels every output by it).
- `tlx_frame`: one row per questionnaire: participant, group, task, condition,
  tlx_raw, tlx_weighted (empty without the pairwise comparisons), tlx_mental ...
- `participant_means`: long format, one row per participant x task x condition x measure
  (the mean over that block's trials; TLX values as they are): the unit of analysis.
"""

from __future__ import annotations

import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.tlx import TLX_SUBSCALES
from db.models.trial import Trial

TRIAL_MEASURES = ("completion_time_s", "peak_proximal_force_n", "peak_distal_force_n")
TLX_MEASURES = ("tlx_raw", "tlx_weighted", *(f"tlx_{s}" for s in TLX_SUBSCALES))
MEASURES = TRIAL_MEASURES + TLX_MEASURES


def trial_frame(engine: Engine) -> pd.DataFrame:
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
            "completion_time_s": t.completion_time_s,
            "peak_proximal_force_n": t.peak_proximal_force_n,
            "peak_distal_force_n": t.peak_distal_force_n,
            "success": bool(t.success),
            "driver": t.driver,
        }
    return pd.DataFrame(
        list(latest.values()),
        columns=["participant", "group", "task", "condition", "trial", *TRIAL_MEASURES, "success",
                 "driver"],
    )


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
    withdrawn participant who had data in it (their data stay in the database)."""
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
    keep_trials = trials[~trials["participant"].isin(list(withdrawn))]
    keep_tlx = tlx[~tlx["participant"].isin(list(withdrawn))]
    return keep_trials.reset_index(drop=True), keep_tlx.reset_index(drop=True), notes


def participant_means(trials: pd.DataFrame, tlx: pd.DataFrame) -> pd.DataFrame:
    """Long format: participant, group, task, condition, measure, value."""
    keys = ["participant", "group", "task", "condition"]
    parts = []
    if len(trials):
        means = trials.groupby(keys, as_index=False)[list(TRIAL_MEASURES)].mean()
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
