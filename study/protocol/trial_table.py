"""The measured trials of a study database as one table, each task's measures under
their own names (`study.protocol.tasks`).

`trial_frame` is what the export writes (`trials.csv`) and what the analysis starts
from (`study.analysis.frames` builds the TLX and per-participant frames on it); it
lives here, below both, so that the export and the exchange read no analysis module.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import pandas as pd
from sqlalchemy import Engine

from study.protocol.study_rows import TRIAL_KEYS, measure_columns, trial_rows

__all__ = ["TRIAL_KEYS", "driver_connection", "measure_columns", "trial_frame", "trial_table"]


def trial_frame(engine: Engine, tasks: Iterable[str] = ()) -> pd.DataFrame:
    """The measured trials; the measure columns of `tasks` and of every task with trials."""
    with driver_connection(engine) as conn:
        rows = trial_rows(conn)
    return trial_table(rows, tasks)


def trial_table(rows: list[dict[str, Any]], tasks: Iterable[str] = ()) -> pd.DataFrame:
    """`trial_rows` as a frame with the columns of `trial_frame`."""
    names = list(dict.fromkeys([*tasks, *(r["task"] for r in rows)]))
    columns = [*TRIAL_KEYS, "block", *measure_columns(names), "success", "driver"]
    return pd.DataFrame(rows, columns=columns)


@contextmanager
def driver_connection(engine: Engine) -> Iterator[Any]:
    """The engine's DBAPI connection (sqlite3 or psycopg), for `study_rows`' plain SQL."""
    conn = engine.raw_connection()
    try:
        yield conn
    finally:
        conn.close()
