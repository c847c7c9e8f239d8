"""The measured trials of a study database as one table, each task's measures under
their own names (`study.protocol.tasks`).

`trial_frame` is what the export writes (`trials.csv`) and what the analysis starts
from (`study.analysis.frames` builds the TLX and per-participant frames on it); it
lives here, below both, so that the export and the exchange read no analysis module.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import Trial
from study.protocol.tasks import COMPLETION_TIME, get_task

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
        latest: dict[tuple[str, str, str, int], dict[str, Any]] = {}
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
