"""The study's measured (or imported, or simulated) trials of one task, as the fit reads them.

The trials are `frames.trial_frame`'s (completed, not practice, the latest attempt of
each slot), so the fit sees what the analysis sees, withdrawn participants left out as
the analysis leaves them. The trial measures are used (an imported study may have no
samples; `with_features` adds the task's behavioural features where the samples are
stored, read in bounded memory by `db.sample_reader.SampleReader`). Beside them: each
participant's condition order (which condition's block came
first, from the trials' block index) and each trial's position in the participant's
session (0, 1, ... over the measured trials of the task in the order they were run),
for the checks of what the participant model lacks (`checks.py`).

A person's moments are the mean over their trials of each log measure (and feature) per
condition.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import pyarrow as pa
from sqlalchemy import Engine, exists, func, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import SampleChunk, Trial
from db.sample_reader import SampleReader
from study.analysis.frames import trial_frame, without_withdrawn
from study.analysis.participant_fit.emulator import floor, log_moment, moment_names
from study.analysis.participant_fit.estimate import expanded_interval
from study.analysis.source import DataSource
from study.errors import StudyInputError
from study.protocol.design import KNOWN_CONDITIONS
from study.protocol.tasks import get_task
from study.protocol.traits import PROFILES
from teleop_core.progress import Progress, no_progress

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


def with_features(
    engine: Engine, trials: pd.DataFrame, task: str, progress: Progress = no_progress
) -> tuple[pd.DataFrame, dict[str, int]]:
    """`trials` with the task's fit features read off each trial's stored samples (NaN
    for a trial without samples: an imported one), and the counts of trials with and
    without samples."""
    the_task = get_task(task)
    names = list(the_task.fit_features)
    out = trials.assign(**{f: np.nan for f in names})
    if not names or not len(trials):
        return out, {"with_samples": 0, "without_samples": len(trials)}
    recorded = exists().where(SampleChunk.trial_id == Trial.id).label("recorded")
    with Session(engine) as session:
        rows = session.execute(
            select(Participant.code, Trial.condition, Trial.trial_index, Trial.id, recorded)
            .join(Trial, Trial.participant_id == Participant.id)
            .where(Trial.task == task, Trial.status == "completed", Trial.practice.is_(False))
            .order_by(Trial.attempt)
        ).all()
    # the latest attempt of each slot, as `trial_frame` keeps it
    ids = {(code, cond, index + 1): (tid, has) for code, cond, index, tid, has in rows}
    keys = list(zip(trials["participant"], trials["condition"], trials["trial"], strict=True))
    todo = [(i, ids[key][0]) for i, key in enumerate(keys) if key in ids and ids[key][1]]
    context = the_task.session_context()
    values = np.full((len(trials), len(names)), np.nan)
    with SampleReader(engine) as reader:
        for done, (i, tid) in enumerate(todo):
            table = the_task.sample_table(pa.Table.from_batches(list(reader.trial(tid))))
            features = the_task.trial_features(table.to_pandas(), context)
            values[i] = [features.get(f, np.nan) for f in names]
            progress("samples", done + 1, len(todo))
    out[names] = values
    return out, {"with_samples": len(todo), "without_samples": len(trials) - len(todo)}


def person_moments(
    trials: pd.DataFrame, measures: Sequence[str], features: Sequence[str] = ()
) -> pd.DataFrame:
    """One row per participant with both conditions: group, order, k (trials per
    condition, the smaller count) and each moment (`CONDITION:measure`, then
    `CONDITION:feature`; log scale; a feature's mean over the trials that define it,
    NaN where none does)."""
    columns = [*measures, *features]
    logged = trials.assign(**{c: log_moment(trials[c], floor(c, measures)) for c in columns})
    means = logged.groupby(["participant", "condition"])[columns].mean().unstack()
    counts = trials.groupby(["participant", "condition"]).size().unstack()
    keep = counts.dropna().index
    out = pd.DataFrame(index=keep)
    for name in [*moment_names(measures), *moment_names(features)]:
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
    values: np.ndarray, rng: np.random.Generator, n_boot: int, positive: bool = False
) -> tuple[float, float]:
    """95 % interval of the mean of `values` over resampled people: the expanded
    percentile interval (`estimate.expanded_interval`), as the fitted means' are. A
    plain percentile interval of a mean over the few people of a group (8 in a 20/8/8
    study, as many per group as the fit's check simulates) holds the mean less often
    than it claims, and the emulator check (`checks.emulator_check`) then counted an
    unbiased emulator's predictions outside it. `positive`: a positive measure's mean,
    its interval on the log scale (`expanded_interval`), so that it stays above zero."""
    if len(values) < 2:
        return float("nan"), float("nan")
    idx = rng.integers(0, len(values), (n_boot, len(values)))
    low, high = expanded_interval(values[idx].mean(axis=1), len(values), positive=positive)
    return float(low), float(high)
