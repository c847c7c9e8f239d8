"""Export of trial samples in bounded memory: one file, or one file per trial.

`study export --samples` used to hold the whole samples table in a DataFrame (1.97 GB
for the million samples of the demo study). Here the samples go from
`db.samples.SampleReader` (Arrow batches of at most 65,536 rows, one trial at a time)
straight into pyarrow's incremental writers (`parquet.ParquetWriter`,
`csv.CSVWriter`), so memory stays at a batch plus one Parquet row group whatever the
size of the study. pyarrow does the writing because it already is the Parquet
dependency and its CSV writer formats a batch in C++; pandas' `to_csv` per chunk would
take most of the time.

The column contract (other tools rely on it; keep it exactly):

- samples: participant, task, condition, trial, seq, then `db.models.trial.SAMPLE_COLUMNS`

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
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import SAMPLE_COLUMNS, Trial
from db.samples import SAMPLE_SCHEMA, SampleReader
from study.errors import StudyInputError
from study.protocol.design import StudyDesign
from study.protocol.export_files import AtomicFile, escape_array, refuse_symlink

SAMPLE_EXPORT_COLUMNS = ("participant", "task", "condition", "trial", "seq", *SAMPLE_COLUMNS)
_KEY_FIELDS = [
    pa.field("participant", pa.string()),
    pa.field("task", pa.string()),
    pa.field("condition", pa.string()),
    pa.field("trial", pa.int64()),
]
SAMPLE_EXPORT_SCHEMA = pa.schema([*_KEY_FIELDS, *SAMPLE_SCHEMA])
ROW_GROUP_ROWS = 131_072
"""Samples per Parquet row group (about 15 MB in memory while it is encoded)."""

Progress = Callable[[int, int], None]
"""Called as `progress(trials_done, trials_total)` after each trial."""


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


class _StagedFile:
    """An incremental CSV or Parquet writer into an `AtomicFile`, renamed to NAME on commit."""

    def __init__(self, path: Path, fmt: str) -> None:
        self.path = path
        self._out = AtomicFile(path)
        self.tmp = self._out.tmp
        self.fmt = fmt
        self.rows = 0
        self._row_group_rows = ROW_GROUP_ROWS
        self._pending: list[pa.RecordBatch] = []
        self._pending_rows = 0
        if fmt == "parquet":
            # Dictionary encoding only for the text columns: tried on every float column
            # (pyarrow's default) it took 80 % of the writing time and gave a larger file.
            self._writer: pq.ParquetWriter | pa_csv.CSVWriter = pq.ParquetWriter(
                self._out.file,
                SAMPLE_EXPORT_SCHEMA,
                compression="snappy",
                use_dictionary=["participant", "task", "condition", "branch"],
            )
        else:
            # The header as pandas wrote it (unquoted); values quoted where pyarrow needs.
            self._out.file.write((",".join(SAMPLE_EXPORT_SCHEMA.names) + "\n").encode())
            self._writer = pa_csv.CSVWriter(
                self._out.file,
                SAMPLE_EXPORT_SCHEMA,
                write_options=pa_csv.WriteOptions(include_header=False),
            )
        self._closed = False

    def write(self, batch: pa.RecordBatch) -> None:
        self.rows += batch.num_rows
        if self.fmt == "csv":
            # text a spreadsheet would run gets a leading quote (export_files)
            self._writer.write_batch(
                pa.RecordBatch.from_arrays(
                    [escape_array(c) for c in batch.columns], schema=batch.schema
                )
            )
            return
        # Parquet: one row group per ROW_GROUP_ROWS samples, not one per (small) batch.
        self._pending.append(batch)
        self._pending_rows += batch.num_rows
        if self._pending_rows >= self._row_group_rows:
            self._flush()

    def _flush(self) -> None:
        if self._pending:
            table = pa.Table.from_batches(self._pending, schema=SAMPLE_EXPORT_SCHEMA)
            self._writer.write_table(table, row_group_size=max(len(table), 1))
            self._pending, self._pending_rows = [], 0

    def commit(self) -> Path:
        self._flush()
        self._close()
        return self._out.commit()

    def abort(self) -> None:
        self._pending = []
        try:
            self._close()
        finally:
            self._out.abort()

    def _close(self) -> None:
        if not self._closed:
            self._closed = True
            self._writer.close()


def _keyed(trial: ExportTrial, batch: pa.RecordBatch) -> pa.RecordBatch:
    n = batch.num_rows
    keys = [
        pa.repeat(pa.scalar(trial.participant, pa.string()), n),
        pa.repeat(pa.scalar(trial.task, pa.string()), n),
        pa.repeat(pa.scalar(trial.condition, pa.string()), n),
        pa.repeat(pa.scalar(trial.trial, pa.int64()), n),
    ]
    return pa.RecordBatch.from_arrays([*keys, *batch.columns], schema=SAMPLE_EXPORT_SCHEMA)


def _stream(
    reader: SampleReader, trial: ExportTrial, selection: SampleSelection, out: _StagedFile
) -> None:
    for batch in reader.trial(trial.trial_id, from_s=selection.from_s, to_s=selection.to_s):
        out.write(_keyed(trial, batch))


def write_samples(
    engine: Engine,
    trials: list[ExportTrial],
    path: Path,
    fmt: str,
    selection: SampleSelection = SampleSelection(),
    *,
    progress: Progress | None = None,
    batch_rows: int = 65_536,
) -> int:
    """Write the samples of `trials` into one file at `path`; returns the number of rows.

    The file appears only when complete (written as `.NAME.partial`, then renamed).
    """
    out = _StagedFile(path, fmt)
    try:
        with SampleReader(engine, batch_rows=batch_rows) as reader:
            for done, trial in enumerate(trials, 1):
                _stream(reader, trial, selection, out)
                if progress is not None:
                    progress(done, len(trials))
        out.commit()
    except BaseException:
        out.abort()
        raise
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
    progress: Progress | None = None,
    batch_rows: int = 65_536,
) -> PerTrialResult:
    """One file per trial in `folder` (`P001_lcca_HV_trial1.parquet`, ...).

    A trial's file is renamed into place only when complete, so a file that exists is
    whole: a rerun after an interruption skips it and writes the rest.
    """
    folder.mkdir(parents=True, exist_ok=True)
    for trial in trials:  # a link anywhere refuses the export before a file is written
        refuse_symlink(folder / f"{trial.file_stem}.{fmt}")
    written, skipped, rows = [], [], 0
    with SampleReader(engine, batch_rows=batch_rows) as reader:
        for done, trial in enumerate(trials, 1):
            path = folder / f"{trial.file_stem}.{fmt}"
            if path.exists():
                skipped.append(path)
            else:
                out = _StagedFile(path, fmt)
                try:
                    _stream(reader, trial, selection, out)
                    written.append(out.commit())
                except BaseException:
                    out.abort()
                    raise
                rows += out.rows
            if progress is not None:
                progress(done, len(trials))
    return PerTrialResult(written, skipped, rows)
