"""The rows the analysis reads from a study database, with plain SQL over a DBAPI
connection (sqlite3, or the driver connection of a SQLAlchemy engine): three queries,
no ORM and no pandas, so that `study analyze` loads neither. `trial_table.trial_frame`
and `analysis.frames` build their frames from these rows.

- `trial_rows`: one dict per measured trial (completed, not practice, the latest attempt
  of each slot): participant, group, task, condition, trial (1-based), block (the
  block's place in the participant's schedule, 1-based), completion_time_s, the trial's
  measures under their names, success, driver, forces (`forces_source`: measured on a
  physical phantom, or simulated), end (`trial_end`: who ended a physical-phantom trial,
  else None).
- `tlx_rows`: one dict per questionnaire in the order stored: participant, group, task,
  condition, the six ratings, tlx_raw, tlx_weighted (None without the pairwise
  comparisons).
- `withdrawn_rows`: code -> withdrawal reason of every withdrawn participant.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from typing import Any

from db.tlx_subscales import TLX_SUBSCALES
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


TRIALS_SQL = (
    'SELECT p.code, p."group", t.id, t.task, t.condition, t.block_index, t.trial_index, '
    "t.completion_time_s, t.success, t.driver, t.summary "
    "FROM participants p JOIN trials t ON t.participant_id = p.id "
    "WHERE t.status = 'completed' AND NOT t.practice "
    "ORDER BY p.code, t.block_index, t.trial_index, t.attempt"
)
MEASURES_SQL = (
    "SELECT m.trial_id, m.name, m.value FROM trial_measures m "
    "JOIN trials t ON t.id = m.trial_id WHERE t.status = 'completed' AND NOT t.practice"
)
TLX_SQL = (
    'SELECT p.code, p."group", r.task, r.condition, '
    + ", ".join(f"r.{s}" for s in TLX_SUBSCALES)
    + ", "
    + ", ".join(f"r.w_{s}" for s in TLX_SUBSCALES)
    + " FROM tlx_responses r JOIN participants p ON p.id = r.participant_id ORDER BY r.id"
)
INVALID_SQL = (
    "SELECT p.code, t.task, t.condition, t.trial_index, t.invalid_reason "
    "FROM participants p JOIN trials t ON t.participant_id = p.id "
    "WHERE t.status = 'completed' AND NOT t.practice "
    "ORDER BY p.code, t.block_index, t.trial_index, t.attempt"
)
WITHDRAWN_SQL = "SELECT code, withdrawal_reason FROM participants WHERE withdrawn_at IS NOT NULL"
DESIGN_SQL = "SELECT design FROM studies ORDER BY id"


def _query(conn: Any, sql: str) -> list[tuple[Any, ...]]:
    cursor = conn.cursor()
    try:
        cursor.execute(sql)
        return cursor.fetchall()
    finally:
        cursor.close()


def forces_source(driver: str | None, summary: Any) -> str:
    """Where a trial's forces came from: `measured` (a drive unit in a physical phantom,
    the lab's force sensors: its summary says ``forces = measured``), `simulated` (the
    follower and phantom models, whoever drove), or `unknown` (an imported trial).
    `summary` is the stored JSON, as text (SQLite) or decoded (PostgreSQL)."""
    summary = _decoded(summary)
    if isinstance(summary, dict) and summary.get("forces") == "measured":
        return "measured"
    return "unknown" if driver == "imported" else "simulated"


TRIAL_ENDS = ("button", "experimenter", "time_limit")
"""How a physical-phantom trial's end was decided (its summary's `end`)."""


def trial_end(summary: Any) -> str | None:
    """Who ended a physical-phantom trial (its summary's `end`: the participant's
    `button`, the `experimenter`, or the `time_limit`); None for any other trial, whose
    success its phantom's model decided."""
    summary = _decoded(summary)
    end = summary.get("end") if isinstance(summary, dict) else None
    return end if end in TRIAL_ENDS else None


def _decoded(summary: Any) -> Any:
    """The stored JSON summary, as text (SQLite) or decoded (PostgreSQL); None if it is
    no JSON."""

    if isinstance(summary, str | bytes):
        try:
            return json.loads(summary)
        except ValueError:
            return None
    return summary


def trial_rows(conn: Any) -> list[dict[str, Any]]:
    measures: dict[int, dict[str, float]] = {}
    for trial_id, name, value in _query(conn, MEASURES_SQL):
        measures.setdefault(trial_id, {})[name] = value
    latest: dict[tuple[Any, ...], dict[str, Any]] = {}
    for row in _query(conn, TRIALS_SQL):
        code, group, trial_id, task, condition, block, index, time_s, success, driver = row[:10]
        latest[(code, task, condition, index)] = {
            "participant": code,
            "group": group,
            "task": task,
            "condition": condition,
            "trial": index + 1,
            "block": block + 1,
            COMPLETION_TIME: time_s,
            **measures.get(trial_id, {}),
            "success": bool(success),
            "driver": driver,
            "forces": forces_source(driver, row[10]),
            "end": trial_end(row[10]),
        }
    return list(latest.values())


def raw_tlx(ratings: dict[str, int]) -> float:
    """Mean of the six ratings."""
    return sum(ratings[s] for s in TLX_SUBSCALES) / len(TLX_SUBSCALES)


def weighted_tlx(ratings: dict[str, int], weights: dict[str, int]) -> float:
    """sum(weight x rating) / 15."""
    return sum(weights[s] * ratings[s] for s in TLX_SUBSCALES) / 15.0


def tlx_rows(conn: Any) -> list[dict[str, Any]]:
    k = len(TLX_SUBSCALES)
    rows = []
    for code, group, task, condition, *values in _query(conn, TLX_SQL):
        ratings = dict(zip(TLX_SUBSCALES, values[:k], strict=True))
        weights = dict(zip(TLX_SUBSCALES, values[k:], strict=True))
        weighted = weighted_tlx(ratings, weights) if weights["mental"] is not None else None
        rows.append(
            {
                "participant": code,
                "group": group,
                "task": task,
                "condition": condition,
                **ratings,
                "tlx_raw": raw_tlx(ratings),
                "tlx_weighted": weighted,
            }
        )
    return rows


def design_analysis(conn: Any) -> dict[str, Any]:
    """The stored design's `[analysis]` table ({} when it has none)."""

    rows = _query(conn, DESIGN_SQL)
    if not rows:
        return {}
    design = rows[0][0]
    design = json.loads(design) if isinstance(design, str) else design
    return dict(design.get("analysis", {}))


def withdrawn_rows(conn: Any) -> dict[str, str]:
    return {code: reason or "" for code, reason in _query(conn, WITHDRAWN_SQL)}


def invalid_rows(conn: Any) -> dict[tuple[str, str, str, int], str]:
    """(code, task, condition, trial number from 1) -> reason, for every trial that
    `trial_rows` keeps (the latest completed attempt) and that is marked invalid
    (`study.protocol.corrections`)."""
    latest: dict[tuple[str, str, str, int], str | None] = {}
    for code, task, condition, index, reason in _query(conn, INVALID_SQL):
        latest[(code, task, condition, index + 1)] = reason
    return {key: reason for key, reason in latest.items() if reason is not None}
