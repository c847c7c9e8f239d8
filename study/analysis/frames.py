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

from study.analysis.means import (
    KEYS,
    TLX_MEASURES,
    participant_mean_rows,
    tlx_measure_rows,
    withdrawal_notes,
    without_invalid_rows,
)
from study.protocol.study_rows import invalid_rows, tlx_rows
from study.protocol.trial_table import (
    TRIAL_KEYS,
    driver_connection,
    measure_columns,
    trial_frame,
)

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


def trial_measures(trials: pd.DataFrame) -> list[str]:
    """The analysed measure columns of the tasks in `trials`."""
    return measure_columns(trials["task"].unique().tolist(), analysed_only=True)


def tlx_frame(engine: Engine) -> pd.DataFrame:
    with driver_connection(engine) as conn:
        rows = tlx_measure_rows(tlx_rows(conn))
    return pd.DataFrame(rows, columns=[*KEYS, *TLX_MEASURES])


def without_withdrawn(
    engine: Engine, trials: pd.DataFrame, tlx: pd.DataFrame
) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """The frames without withdrawn participants, and one exclusion note per task and
    withdrawn participant who had data in it (their data stay in the database); one
    withdrawn before any data is listed too, so every withdrawal is accounted for. The
    trials marked invalid (`study.protocol.corrections.mark_trial`) are left out as
    well, each listed with its reason."""
    # lazy: study.protocol.withdrawal (with sqlalchemy) costs 0.2 s at start-up
    from study.protocol.withdrawal import withdrawn_participants

    withdrawn = withdrawn_participants(engine)
    columns = ["participant", "task"]
    notes = withdrawal_notes(
        withdrawn, trials[columns].to_dict("records"), tlx[columns].to_dict("records")
    )
    keep_trials = trials[~trials["participant"].isin(list(withdrawn))]
    keep_tlx = tlx[~tlx["participant"].isin(list(withdrawn))]
    keep_trials, invalid = _without_invalid(engine, keep_trials)
    return keep_trials.reset_index(drop=True), keep_tlx.reset_index(drop=True), notes + invalid


def _without_invalid(engine: Engine, trials: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """`trials` without the trials marked invalid, and one exclusion note per trial."""

    with driver_connection(engine) as conn:
        invalid = invalid_rows(conn)
    if not invalid or not len(trials):
        return trials, []
    kept, notes = without_invalid_rows(invalid, trials.to_dict("records"))
    return pd.DataFrame(kept, columns=trials.columns), notes


def participant_means(trials: pd.DataFrame, tlx: pd.DataFrame) -> pd.DataFrame:
    """Long format: participant, group, task, condition, measure, value
    (`means.participant_mean_rows`)."""
    rows = participant_mean_rows(trials.to_dict("records"), tlx.to_dict("records"))
    return pd.DataFrame(rows, columns=[*KEYS, "measure", "value"])
