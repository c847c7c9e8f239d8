"""The study's measured (or imported, or simulated) trials of one task, as the fit reads them.

The trials are `frames.trial_frame`'s (completed, not practice, the latest attempt of
each slot), so the fit sees what the analysis sees, withdrawn participants left out as
the analysis leaves them. Only trial measures are used (an imported study may have no
samples). Beside them: each participant's condition order (which condition's block came
first, from the trials' block index) and each trial's position in the participant's
session (0, 1, ... over the measured trials of the task in the order they were run),
for the checks of what the participant model lacks (`checks.py`).

A person's moments are the mean over their trials of each log measure per condition.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import Trial
from study.analysis.frames import trial_frame, without_withdrawn
from study.analysis.participant_fit.emulator import log_moment, moment_names
from study.analysis.source import DataSource
from study.errors import StudyInputError
from study.protocol.design import KNOWN_CONDITIONS
from study.protocol.participants import PROFILES

MIN_PER_GROUP = 4
"""The fewest participants (with trials in both conditions) a group needs to be fitted:
a mean and an SD of each moment, with one degree of freedom left over."""


def observed_trials(engine: Engine, task: str) -> pd.DataFrame:
    """The task's measured trials with `order` (VO-first / HV-first) and `position`."""
    trials = trial_frame(engine, [task])
    trials, _, _ = without_withdrawn(engine, trials, trials.iloc[:0])
    trials = trials[trials["task"] == task].copy()
    with Session(engine) as session:
        first = session.execute(
            select(Participant.code, Trial.condition, func.min(Trial.block_index))
            .join(Trial, Trial.participant_id == Participant.id)
            .where(Trial.task == task, Trial.practice.is_(False))
            .group_by(Participant.code, Trial.condition)
        ).all()
    block = {(code, condition): b for code, condition, b in first}
    trials["block"] = [
        block[(p, c)] for p, c in zip(trials["participant"], trials["condition"], strict=True)
    ]
    firsts = trials.sort_values("block").groupby("participant")["condition"].first()
    trials["order"] = trials["participant"].map(firsts + "-first")
    trials = trials.sort_values(["participant", "block", "trial"], kind="stable")
    trials["position"] = trials.groupby("participant").cumcount()
    return trials.reset_index(drop=True)


def check_fittable(trials: pd.DataFrame, task: str, db_label: str) -> list[str]:
    """The groups to fit, or one line saying why the data cannot be fitted."""
    if not len(trials):
        raise StudyInputError(
            f"no completed {task} trials in {db_label}; expected a study "
            f"with measured {task} trials in VO and HV"
        )
    both = trials.groupby(["group", "participant"])["condition"].nunique()
    complete = both[both == len(KNOWN_CONDITIONS)].groupby(level=0).size()
    groups = list(dict.fromkeys(trials["group"]))
    unknown = [g for g in groups if g not in PROFILES]
    if unknown:
        raise StudyInputError(
            f"group {unknown[0]!r} has no prior profile; expected groups of {', '.join(PROFILES)}"
        )
    for group in groups:
        n = int(complete.get(group, 0))
        if n < MIN_PER_GROUP:
            raise StudyInputError(
                f"group {group} has {n} participant(s) with {task} trials in both VO and HV; "
                f"expected at least {MIN_PER_GROUP} per group to fit its trait distribution"
            )
    return [g for g in PROFILES if g in groups]


def person_moments(trials: pd.DataFrame, measures: Sequence[str]) -> pd.DataFrame:
    """One row per participant with both conditions: group, order, k (trials per
    condition, the smaller count) and each moment (`CONDITION:measure`, log scale)."""
    logged = trials.assign(**{m: log_moment(trials[m]) for m in measures})
    means = logged.groupby(["participant", "condition"])[list(measures)].mean().unstack()
    counts = trials.groupby(["participant", "condition"]).size().unstack()
    keep = counts.dropna().index
    out = pd.DataFrame(index=keep)
    for name in moment_names(measures):
        condition, measure = name.split(":", 1)
        out[name] = means.loc[keep, (measure, condition)]
    people = trials.drop_duplicates("participant").set_index("participant")
    out.insert(0, "k", counts.loc[keep].min(axis=1).astype(int))
    out.insert(0, "order", people.loc[keep, "order"])
    out.insert(0, "group", people.loc[keep, "group"])
    return out


def data_source(trials: pd.DataFrame) -> tuple[str, dict[str, object]]:
    """`measured`, `simulated` or `mixed` (MODEL.json's `data_source`), and the counts."""
    source = DataSource.of(trials)
    kind = (
        "simulated"
        if source.simulated == source.total
        else "measured"
        if source.simulated == 0
        else "mixed"
    )
    return kind, source.to_dict()


def bootstrap_means(
    values: np.ndarray, rng: np.random.Generator, n_boot: int
) -> tuple[float, float]:
    """95 % percentile interval of the mean of `values` over resampled people."""
    if len(values) < 2:
        return float("nan"), float("nan")
    idx = rng.integers(0, len(values), (n_boot, len(values)))
    low, high = np.percentile(values[idx].mean(axis=1), [2.5, 97.5])
    return float(low), float(high)
