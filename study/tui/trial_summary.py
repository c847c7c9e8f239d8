"""What the run screen says when a trial ends: the trial's own figures, and at the end of
a block the block's summary.

`trial_report(engine, trial_id)` reads the stored trial (what `study export` will
give, not the live view's estimate): its completion time, success and every measure of
its task (the peaks among them); when the trial completed its block, each measure's
mean and SD over the block's measured trials (practice trials and interrupted attempts
left out). `report_lines` lays it out in lines that fit the readout (38 columns, and
as many rows as it has: a long block summary before the trial's own figures).
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.study import ScheduleBlock
from db.models.trial import Trial
from study.protocol.tasks import COMPLETION_TIME, get_task

__all__ = ["BlockStat", "TrialReport", "report_lines", "trial_report"]


@dataclass(frozen=True)
class BlockStat:
    """One measure over a block's measured trials."""

    label: str
    unit: str
    n: int
    mean: float
    sd: float | None
    """Sample SD (n - 1 in the denominator); None for a single trial."""


@dataclass(frozen=True)
class TrialReport:
    trial_id: int
    task: str
    condition: str
    practice: bool
    trial_index: int
    success: bool | None
    measures: list[tuple[str, str, float]]
    """(label, unit, value) of the completion time and each of the task's measures (a
    count, such as wall contacts, as a whole number)."""
    block: list[BlockStat] | None
    """The block's summary when this trial completed it, else None."""


def _value(trial: Trial, name: str) -> float | None:
    value = trial.completion_time_s if name == COMPLETION_TIME else trial.measure_values.get(name)
    return None if value is None or not math.isfinite(value) else float(value)


def trial_report(engine: Engine, trial_id: int) -> TrialReport:
    """The stored figures of trial `trial_id` and, if it ended its block, the block's."""
    with Session(engine) as session:
        trial = session.get_one(Trial, trial_id)
        task = get_task(trial.task)
        measures = [
            (m.label, m.unit, int(v) if m.integer else v)
            for m in task.all_measures
            if (v := _value(trial, m.name)) is not None
        ]
        block = session.get(ScheduleBlock, trial.block_id) if trial.block_id else None
        stats = None
        if block is not None and not trial.practice:
            measured = session.scalars(
                select(Trial)
                .where(
                    Trial.block_id == block.id,
                    Trial.practice.is_(False),
                    Trial.status == "completed",
                )
                .order_by(Trial.trial_index, Trial.attempt)
            ).all()
            last = max(t.trial_index for t in measured) if measured else -1
            # the block is done and this is its last measured trial (a report read later)
            if len(measured) >= block.n_trials and trial.trial_index == last:
                stats = _block_stats(task, measured)
        return TrialReport(
            trial.id,
            trial.task,
            trial.condition,
            trial.practice,
            trial.trial_index,
            trial.success,
            measures,
            stats,
        )


def _block_stats(task, trials: Sequence[Trial]) -> list[BlockStat]:
    stats = []
    for m in task.all_measures:
        values = [v for t in trials if (v := _value(t, m.name)) is not None]
        if values:
            sd = statistics.stdev(values) if len(values) > 1 else None
            stats.append(BlockStat(m.label, m.unit, len(values), statistics.fmean(values), sd))
    return stats


def _number(value: float, unit: str) -> str:
    if isinstance(value, int):
        text = str(value)
    else:
        text = f"{value:.2f}" if abs(value) < 10 else f"{value:.1f}"
    return f"{text} {unit}" if unit else text


def report_lines(code: str, report: TrialReport, rows: int | None = None) -> list[str]:
    """The readout's lines: the trial, then (at a block's end) the block's summary.

    With `rows` (the lines the readout has), a block's summary that does not fit under
    the trial's figures is shown in full and the trial's own figures are left out (its
    line says where they are: the participant page, `v`); a summary longer than `rows`
    ends on a line that counts the measures left out.
    """
    kind = "practice" if report.practice else "trial"
    success = {True: "yes", False: "no", None: "not recorded"}[report.success]
    head = f"{code}: {report.task}/{report.condition} {kind} {report.trial_index + 1} stored"
    lines = [
        head,
        f"  success {success}",
        *(f"  {label} {_number(value, unit)}" for label, unit, value in report.measures),
    ]
    if report.block is None:
        return lines
    block = _block_lines(report)
    if rows is None or len(lines) + len(block) <= rows:
        return lines + block
    lines = [head, f"  success {success} (its figures: v)", *block]
    if len(lines) > rows:
        left = len(lines) - rows + 1
        lines = [*lines[: rows - 1], f"  {left} more measure{'' if left == 1 else 's'}: v"]
    return lines


def _block_lines(report: TrialReport) -> list[str]:
    """The block's summary: its measured trials, each measure's mean ± SD."""
    assert report.block is not None
    n = max(s.n for s in report.block) if report.block else 0
    lines = [
        f"block {report.task}/{report.condition} done:",
        f"  {n} measured trial{'' if n == 1 else 's'}, mean ± SD",
    ]
    for s in report.block:
        spread = "" if s.sd is None else f" ± {_number(s.sd, '').strip()}"
        lines.append(f"  {s.label} {_number(s.mean, '').strip()}{spread} {s.unit}".rstrip())
    return lines
