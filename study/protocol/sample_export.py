"""Export of trial samples in bounded memory: one file, or one file per trial.

`study export --samples` used to hold the whole samples table in a DataFrame (gigabytes
for the million samples of the demo study). Here the samples are read in spans of at
most `SPAN_ROWS` samples (`db.sample_reader.plan_spans`: consecutive trials together, a
long trial in windows) by a few threads (`read_spans`, one connection each), and
written span by span with pyarrow's incremental Parquet writer, one row group per
span, or as CSV text. Memory stays at a few spans whatever the size of the study.

Where the time goes (`study bench export`; its figures are on the Benchmarks page):
decoding the stored chunks (`db.sample_reader`) and Parquet encoding with snappy, each
about half (lz4 or no codec would save little: not worth a file fewer tools read), the
key columns little. The reader threads read and decode, build the key
columns (a `take` of each trial's values by the row's `trial_id`) and, for CSV, format
the text (pyarrow's CSV writer, in C++), so the calling thread only encodes Parquet or
copies bytes to the file. The Parquet encoder writes to a pyarrow file, not a Python
one, so that it never waits for the GIL the readers hold: through a Python file object
the export ran on one core. pyarrow does the writing because
it already is the Parquet dependency; pandas' `to_csv` per chunk would take most of
the time.

The column contract (other tools rely on it; keep it exactly):

- samples: participant, task, condition, trial, seq, then the tasks' own sample columns
  (`study.protocol.tasks.SampleColumn`: each task's in its order, a name two tasks share
  once; empty where a row's task has no such column); a file of one trial (`--per-trial`)
  has its task's columns only. Units and meanings are in the codebook.

Rows are the samples of the measured (non-practice), completed trials, ordered by trial
(as stored) and `seq`. A selection (`SampleSelection`) restricts them to participants,
tasks, conditions, trial numbers and a time range `from_s <= t_s < to_s`. Files are
written under a temporary name, flushed to disk and renamed over the target when
complete (`study.protocol.export_files`), so an error or an interrupt leaves no
half-written file and the previous file intact; a target that is a symbolic link is
refused, and CSV text a spreadsheet would run as a formula gets a leading quote. With
one file per trial, a rerun skips the trials whose file is already there (a resumed
export).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Generator, Iterable
from contextlib import ExitStack, closing
from dataclasses import dataclass
from itertools import chain
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pa_csv
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import Trial
from db.sample_reader import SPAN_ROWS, SampleSpan, plan_spans, read_spans
from study.errors import StudyInputError
from study.protocol.design import StudyDesign
from study.protocol.export_files import StagedTableFile, escape_array, refuse_symlink
from study.protocol.tasks import Task, get_task
from teleop_core.progress import Progress, no_progress

_KEY_FIELDS = [
    pa.field("participant", pa.string()),
    pa.field("task", pa.string()),
    pa.field("condition", pa.string()),
    pa.field("trial", pa.int64()),
]


def sample_export_schema(tasks: Iterable[str]) -> pa.Schema:
    """The samples file's schema for trials of `tasks`: the keys, `seq`, then each task's
    sample columns in its order (a name an earlier task has, once)."""
    fields: dict[str, pa.Field] = {}
    for name in tasks:
        for field in get_task(name).sample_schema():
            fields.setdefault(field.name, field)
    return pa.schema([*_KEY_FIELDS, pa.field("seq", pa.int64(), False), *fields.values()])


def sample_export_columns(tasks: Iterable[str]) -> tuple[str, ...]:
    """The samples file's columns for trials of `tasks` (`sample_export_schema`)."""
    return tuple(sample_export_schema(tasks).names)


def _text_columns(schema: pa.Schema) -> tuple[str, ...]:
    """Dictionary-encoded in Parquet: the text columns (on every float column, pyarrow's
    default, it took most of the writing time and gave a larger file)."""
    return tuple(f.name for f in schema if f.type == pa.string())


MAX_WORKERS = 4
"""Most reader threads by default (one per CPU up to this)."""
CSV_SPAN_ROWS = 16_384
"""Samples per span for CSV: its text (about 230 bytes a sample) is built in the reader
threads and waits its turn, so CSV spans are smaller than Parquet's (`SPAN_ROWS`, one
row group each): spans four times larger nearly doubled the export's added peak memory
(`study bench export`)."""


@dataclass(frozen=True)
class SampleSelection:
    """Which samples to export; an empty tuple or None means no restriction."""

    participants: tuple[str, ...] = ()
    """Participant codes, e.g. ("P001", "P007")."""
    tasks: tuple[str, ...] = ()
    """Task names of the study design."""
    conditions: tuple[str, ...] = ()
    """Condition names of the study design."""
    trials: tuple[int, ...] = ()
    """Measured trial numbers within a task x condition block, from 1."""
    from_s: float | None = None
    """Earliest sample time kept, s since the trial started (inclusive)."""
    to_s: float | None = None
    """Sample times kept are before this, s since the trial started (exclusive)."""

    def __post_init__(self) -> None:
        for name in ("from_s", "to_s"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise StudyInputError(f"{name} {value!r}; expected a time >= 0 s")
        if self.from_s is not None and self.to_s is not None and self.to_s <= self.from_s:
            raise StudyInputError(
                f"time range from {self.from_s:g} s to {self.to_s:g} s is empty; "
                "expected --to-s greater than --from-s"
            )
        for trial in self.trials:
            if trial < 1:
                raise StudyInputError(f"trial {trial}; expected a trial number >= 1")

    @property
    def restricted(self) -> bool:
        return self != SampleSelection()


@dataclass(frozen=True)
class ExportTrial:
    """One trial whose samples are exported, with the key columns of its rows."""

    trial_id: int
    participant: str
    task: str
    condition: str
    trial: int
    attempt: int

    @property
    def file_stem(self) -> str:
        """`P001_lcca_HV_trial1` (plus `_attempt2` for a later completed attempt)."""
        stem = f"{self.participant}_{self.task}_{self.condition}_trial{self.trial}"
        if self.attempt > 1:
            stem += f"_attempt{self.attempt}"
        return re.sub(r"[^A-Za-z0-9_.-]", "-", stem)


def select_trials(
    session: Session, design: StudyDesign, selection: SampleSelection
) -> list[ExportTrial]:
    """The completed measured trials the selection names, in stored order.

    Every name in the selection must exist (a typo would otherwise export nothing).
    """
    _check_names("task", selection.tasks, design.tasks)
    _check_names("condition", selection.conditions, design.conditions)
    beyond = [t for t in selection.trials if t > design.trials_per_condition]
    if beyond:  # a trial no block has: the export would be empty
        raise StudyInputError(
            f"--trial {beyond[0]}; expected 1 to {design.trials_per_condition}, the measured "
            "trials of a block in the design"
        )
    if selection.participants:
        known = set(
            session.scalars(
                select(Participant.code).where(Participant.code.in_(selection.participants))
            )
        )
        unknown = [c for c in selection.participants if c not in known]
        if unknown:
            raise StudyInputError(
                f"unknown participant {unknown[0]!r}; expected a code from `study schedule`"
            )
    query = (
        select(
            Trial.id,
            Participant.code,
            Trial.task,
            Trial.condition,
            Trial.trial_index,
            Trial.attempt,
        )
        .join(Participant, Trial.participant_id == Participant.id)
        .where(Trial.status == "completed", Trial.practice.is_(False))
        .order_by(Trial.id)
    )
    if selection.participants:
        query = query.where(Participant.code.in_(selection.participants))
    if selection.tasks:
        query = query.where(Trial.task.in_(selection.tasks))
    if selection.conditions:
        query = query.where(Trial.condition.in_(selection.conditions))
    if selection.trials:
        query = query.where(Trial.trial_index.in_([t - 1 for t in selection.trials]))
    return [
        ExportTrial(tid, code, task, cond, index + 1, attempt)
        for tid, code, task, cond, index, attempt in session.execute(query)
    ]


def _check_names(what: str, given: Iterable[str], known: tuple[str, ...]) -> None:
    for name in given:
        if name not in known:
            raise StudyInputError(f"{what} {name!r}; expected one of {', '.join(known)}")


_Encoded = tuple[int, "pa.Table | pa.Buffer"]
"""A span ready to write (`StagedTableFile.write`): rows, keyed table or CSV text."""


class _Keys:
    """The key columns of the exported trials, looked up by `trial_id` row by row, and
    each row's values under the export's columns (its task's, by `Task.sample_table`)."""

    def __init__(self, trials: list[ExportTrial], schema: pa.Schema) -> None:
        ids = np.array([t.trial_id for t in trials], dtype=np.int64)
        self._order = np.argsort(ids, kind="stable")
        self._ids = ids[self._order]
        self._values = [
            pa.array([getattr(trials[k], f.name) for k in self._order], f.type) for f in _KEY_FIELDS
        ]
        self._tasks: list[Task] = [get_task(n) for n in dict.fromkeys(t.task for t in trials)]
        index = {t.name: k for k, t in enumerate(self._tasks)}
        self._task_of = np.array([index[trials[k].task] for k in self._order], dtype=np.int64)
        self.schema = schema

    def keyed(self, span: pa.Table) -> pa.Table:
        """`span` (`db.sample_reader.span_schema`) with the key columns in place of
        `trial_id` and the export's sample columns after `seq`."""
        rows = np.searchsorted(self._ids, span.column("trial_id").to_numpy())
        index = pa.array(rows.astype(np.int32))
        keys = [values.take(index) for values in self._values]
        row_task = self._task_of[rows]
        present = np.unique(row_task)
        mapped = {k: self._tasks[k].sample_table(span) for k in present}
        values = []  # each export column: its task's, NULL for a row of a task without it
        for field in list(self.schema)[len(_KEY_FIELDS) + 1 :]:
            column: pa.Array | pa.ChunkedArray = pa.nulls(span.num_rows, field.type)
            for k, table in mapped.items():
                if field.name not in table.column_names:
                    continue
                source = table[field.name].cast(field.type)
                mask = pa.array(row_task == k)
                column = source if len(present) == 1 else pc.if_else(mask, source, column)
            values.append(column)
        return pa.Table.from_arrays([*keys, span["seq"], *values], schema=self.schema)


def _encoder(
    trials: list[ExportTrial], fmt: str, schema: pa.Schema
) -> Callable[[SampleSpan, pa.Table], _Encoded]:
    """The work done on a span in its reader thread."""
    keys = _Keys(trials, schema)
    options = pa_csv.WriteOptions(include_header=False)

    def encode(span: SampleSpan, table: pa.Table) -> _Encoded:
        keyed = keys.keyed(table)
        if fmt == "parquet":
            return keyed.num_rows, keyed
        # text a spreadsheet would run gets a leading quote (export_files)
        escaped = pa.Table.from_arrays([escape_array(c) for c in keyed.columns], schema=schema)
        sink = pa.BufferOutputStream()
        pa_csv.write_csv(escaped, sink, write_options=options)
        return keyed.num_rows, sink.getvalue()

    return encode


def _span(fmt: str, span_rows: int | None) -> int:
    default = SPAN_ROWS if fmt == "parquet" else CSV_SPAN_ROWS
    return default if span_rows is None else span_rows


def default_workers() -> int:
    """Reader threads: one per CPU this process may use, at most `MAX_WORKERS`."""
    return max(1, min(len(os.sched_getaffinity(0)), MAX_WORKERS))


def _read(
    engine: Engine,
    trials: list[ExportTrial],
    plan: list[list[SampleSpan]],
    fmt: str,
    selection: SampleSelection,
    workers: int | None,
    schema: pa.Schema,
) -> Generator[_Encoded, None, None]:
    return read_spans(
        engine,
        chain.from_iterable(plan),
        _encoder(trials, fmt, schema),
        workers=workers or default_workers(),
        from_s=selection.from_s,
        to_s=selection.to_s,
    )


def write_samples(
    engine: Engine,
    trials: list[ExportTrial],
    path: Path,
    fmt: str,
    selection: SampleSelection = SampleSelection(),
    *,
    progress: Progress = no_progress,
    span_rows: int | None = None,
    workers: int | None = None,
    tasks: Iterable[str] = (),
) -> int:
    """Write the samples of `trials` into one file at `path`; returns the number of rows.

    The file's columns are `sample_export_schema` of `tasks` and the trials' tasks.
    `span_rows` bounds the samples read at once (default `SPAN_ROWS` for Parquet,
    `CSV_SPAN_ROWS` for CSV), `workers` the reader threads (default
    `default_workers()`). The file appears only when complete (written as
    `.NAME.partial`, then renamed).
    """
    schema = sample_export_schema(dict.fromkeys([*tasks, *(t.task for t in trials)]))
    with StagedTableFile(path, fmt, schema, _text_columns(schema)) as out:
        plan = plan_spans(engine, [t.trial_id for t in trials], max_rows=_span(fmt, span_rows))
        with closing(_read(engine, trials, plan, fmt, selection, workers, schema)) as parts:
            for done, spans in enumerate(plan, 1):
                for _ in spans:
                    out.write(next(parts))
                progress("samples", done, len(trials))
        out.commit()
    return out.rows


@dataclass(frozen=True)
class PerTrialResult:
    written: list[Path]
    """Files written by this run."""
    skipped: list[Path]
    """Files already there from an earlier run (a resumed export), left as they were."""
    rows: int
    """Samples written by this run."""


def write_samples_per_trial(
    engine: Engine,
    trials: list[ExportTrial],
    folder: Path,
    fmt: str,
    selection: SampleSelection = SampleSelection(),
    *,
    progress: Progress = no_progress,
    span_rows: int | None = None,
    workers: int | None = None,
) -> PerTrialResult:
    """One file per trial in `folder` (`P001_lcca_HV_trial1.parquet`, ...).

    A trial's file is renamed into place only when complete, so a file that exists is
    whole: a rerun after an interruption skips it and writes the rest (without reading
    its samples).
    """
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / f"{trial.file_stem}.{fmt}" for trial in trials]
    for path in paths:  # a link anywhere refuses the export before a file is written
        refuse_symlink(path)
    missing = [not path.exists() for path in paths]
    todo = [t for t, m in zip(trials, missing, strict=True) if m]
    plan = plan_spans(
        engine, [t.trial_id for t in todo], max_rows=_span(fmt, span_rows), join_trials=False
    )
    spans_of = {t.trial_id: spans for t, spans in zip(todo, plan, strict=True)}
    written, skipped, rows = [], [], 0
    schemas = {name: sample_export_schema([name]) for name in dict.fromkeys(t.task for t in todo)}
    parts_of = {
        name: closing(
            _read(
                engine,
                [t for t in todo if t.task == name],
                [spans_of[t.trial_id] for t in todo if t.task == name],
                fmt,
                selection,
                workers,
                schema,
            )
        )
        for name, schema in schemas.items()
    }
    with ExitStack() as stack:
        parts = {name: stack.enter_context(p) for name, p in parts_of.items()}
        for done, (trial, path, m) in enumerate(zip(trials, paths, missing, strict=True), 1):
            if not m:
                skipped.append(path)
            else:
                schema = schemas[trial.task]
                with StagedTableFile(path, fmt, schema, _text_columns(schema)) as out:
                    for _ in spans_of[trial.trial_id]:
                        out.write(next(parts[trial.task]))
                    written.append(out.commit())
                rows += out.rows
            progress("samples", done, len(trials))
    return PerTrialResult(written, skipped, rows)
