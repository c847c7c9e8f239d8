"""Reading trials' sample streams as Arrow record batches in bounded memory: one trial,
or many trials in spans read by a pool of threads and handed back in order.

Samples are stored per committed chunk, each a compressed Arrow record batch
(`db.sample_codec`). A reader selects the chunks it needs (by trial, sequence number
and time, from the key and two stored times, without decoding the others), decodes
them and cuts the rows outside the request: memory is a few chunks plus the batch
being built. Reading a row per sample through a database driver had cost about 1.1 us
of CPU per sample (half in SQLite decoding records, half in the driver's call per
value), which held `study export --samples` below a million samples a second (issue
26); a chunk is one row and one decompression for up to a second of samples.

Reading many trials (`study export --samples`):

- `plan_spans` cuts the trials into spans of at most `max_rows` samples: consecutive
  small trials together, a long trial in windows of `seq`. A span's size is known
  before it is read (each trial's first and last `seq`, from the chunks' key), so
  memory is bounded by construction, however the samples are spread over the trials.
- `read_spans` reads spans with several threads, each with its own connection (zstd
  and pyarrow release the GIL while they decompress and copy), keeps at most
  `workers + 1` spans in flight and runs the caller's function on each span in the
  worker thread (building key columns, formatting CSV), so that the calling thread
  only writes.

Python's concurrent.futures does the pool; what is written here is the bounded,
ordered hand-back, which it does not offer (`Executor.map` submits every item at once).
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
import pyarrow as pa
from sqlalchemy import ColumnElement, Connection, Engine, func, select
from sqlalchemy.orm import Session

from db.errors import DbInputError
from db.models.trial import SampleChunk, SampleSchema, Trial
from db.sample_codec import decode, read_schema


def sample_schema(chunk_schema: pa.Schema) -> pa.Schema:
    """Arrow schema of the batches `SampleReader.trial` yields of chunks of
    `chunk_schema` (the trial's task's columns): `seq`, then the chunk's columns."""
    return pa.schema([pa.field("seq", pa.int64(), False), *chunk_schema])


def span_schema(chunk_schema: pa.Schema) -> pa.Schema:
    """Arrow schema of a span's table: `trial_id`, `seq`, then the chunk's columns."""
    return pa.schema([pa.field("trial_id", pa.int64(), False), *sample_schema(chunk_schema)])


_NO_SAMPLES = pa.schema([pa.field("t_s", pa.float64(), False)])
"""The chunk schema of a span whose trials have no stored samples: the one column every
chunk schema has."""

_BATCH_ROWS = 65_536
SPAN_ROWS = 65_536
"""Default most samples in one span (about 7 MB as Arrow columns)."""

T = TypeVar("T")


@dataclass(frozen=True)
class SampleSpan:
    """Samples read by one query: whole trials, or a window of `seq` of one trial."""

    trial_ids: tuple[int, ...]
    """Trials in ascending id order (one when the span is a window), all of one schema."""
    seq_from: int | None = None
    """First `seq` of the window (inclusive); None for whole trials."""
    seq_to: int | None = None
    """End of the window (exclusive); None for whole trials."""
    rows: int = 0
    """Most samples the span can hold (from the trials' first and last `seq`)."""
    schema_id: int | None = field(default=None, compare=False)
    """The stored schema of the span's chunks (`sample_schemas.id`); not part of what
    the span reads (trials and window), so not compared."""


class SampleReader:
    """Read trials' sample streams as Arrow record batches of at most `batch_rows` rows.

    Parameters
    ----------
    engine
        Engine of the study database (the reader holds one connection of its own).
    batch_rows
        Most rows in one batch, > 0. Memory held by the reader is about
        `batch_rows` x 100 bytes plus a few stored chunks.

    Use as a context manager; one reader serves any number of `trial` or `span` calls
    from one thread at a time.
    """

    def __init__(self, engine: Engine, *, batch_rows: int = _BATCH_ROWS) -> None:
        if batch_rows < 1:
            raise DbInputError(f"batch_rows {batch_rows!r} is not a positive number of rows")
        self.batch_rows = batch_rows
        self._conn: Connection = engine.connect()
        self._schemas: dict[int, pa.Schema] = {}

    def schema(self, schema_id: int) -> pa.Schema:
        """The chunk schema stored as `schema_id` (read once per reader)."""
        if schema_id not in self._schemas:
            data = self._conn.execute(
                select(SampleSchema.data).where(SampleSchema.id == schema_id)
            ).scalar_one()
            self._conn.rollback()
            self._schemas[schema_id] = read_schema(data)
        return self._schemas[schema_id]

    def trial_schema(self, trial_id: int) -> pa.Schema | None:
        """The chunk schema of `trial_id`'s samples (its task's columns); None without any."""
        schema_id = self._conn.execute(
            select(SampleChunk.schema_id).where(SampleChunk.trial_id == int(trial_id)).limit(1)
        ).scalar()
        self._conn.rollback()
        return None if schema_id is None else self.schema(int(schema_id))

    def trial(
        self, trial_id: int, *, from_s: float | None = None, to_s: float | None = None
    ) -> Iterator[pa.RecordBatch]:
        """The samples of one trial in `seq` order, with `from_s <= t_s < to_s` when given;
        batches of `sample_schema` of the trial's chunk schema (`trial_schema`)."""
        pending: list[pa.RecordBatch] = []
        held = 0
        schema = None
        for group in _batched(self._chunks([int(trial_id)], None, None, from_s, to_s), 64):
            table = _joined(group, None, None, from_s, to_s).drop_columns(["trial_id"])
            schema = table.schema
            pending += table.to_batches()
            held += table.num_rows
            if held >= self.batch_rows:
                table = pa.Table.from_batches(pending, schema=schema).combine_chunks()
                full = held - held % self.batch_rows
                yield from table.slice(0, full).to_batches(max_chunksize=self.batch_rows)
                pending = table.slice(full).to_batches()
                held -= full
        if held:
            table = pa.Table.from_batches(pending, schema=schema)
            yield from table.combine_chunks().to_batches(max_chunksize=self.batch_rows)

    def span(
        self, span: SampleSpan, *, from_s: float | None = None, to_s: float | None = None
    ) -> pa.Table:
        """A span's samples (`span_schema` of its chunks' schema) in trial and `seq` order,
        `from_s <= t_s < to_s`; none read, an empty table of the span's stored schema
        (`span.schema_id`, else its trials', else `t_s` alone: they have no samples)."""
        trial_ids = list(span.trial_ids)
        chunks = list(self._chunks(trial_ids, span.seq_from, span.seq_to, from_s, to_s))
        if chunks:
            return _joined(chunks, span.seq_from, span.seq_to, from_s, to_s)
        if span.schema_id is not None:
            return span_schema(self.schema(span.schema_id)).empty_table()
        stored = list(self._stored_schemas(trial_ids).values())
        return span_schema(stored[0] if stored else _NO_SAMPLES).empty_table()

    def _chunks(
        self,
        trial_ids: list[int],
        seq_from: int | None,
        seq_to: int | None,
        from_s: float | None,
        to_s: float | None,
    ) -> Iterator[_Chunk]:
        """Each stored chunk the request touches, decoded, in trial and `seq` order.

        The work per chunk is kept to the fetch and the decoding: the key columns and
        the cut to the request are done once for many chunks (`_joined`), since a
        Python step per chunk costs as much as decoding a 100-sample chunk.
        """
        c = SampleChunk
        query = select(c.trial_id, c.first_seq, c.raw_bytes, c.schema_id, c.data).where(
            c.trial_id.in_(trial_ids)
        )
        if seq_from is not None:
            query = query.where(c.first_seq + c.n_samples > seq_from)
        if seq_to is not None:
            query = query.where(c.first_seq < seq_to)
        query = query.where(*_time_range(from_s, to_s)).order_by(c.trial_id, c.first_seq)
        # a few chunks at a time from the driver: memory stays a few chunks
        schemas = self._stored_schemas(trial_ids)
        rows = self._conn.execution_options(yield_per=16).execute(query)
        try:
            for trial_id, first_seq, raw_bytes, schema_id, data in rows:
                yield trial_id, first_seq, decode(data, raw_bytes, schemas[schema_id])
        finally:
            rows.close()
            self._conn.rollback()

    def _stored_schemas(self, trial_ids: list[int]) -> dict[int, pa.Schema]:
        """The schemas of the trials' chunks, by id (read before the chunks' cursor opens)."""
        ids = (
            self._conn.execute(
                select(SampleChunk.schema_id).where(SampleChunk.trial_id.in_(trial_ids)).distinct()
            )
            .scalars()
            .all()
        )
        self._conn.rollback()
        return {int(i): self.schema(int(i)) for i in ids}

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> SampleReader:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _time_range(from_s: float | None, to_s: float | None) -> list[ColumnElement[bool]]:
    """Conditions on the chunks that may hold samples with `from_s <= t_s < to_s`."""
    where = []
    for name, value in (("from_s", from_s), ("to_s", to_s)):
        if value is None:
            continue
        if not math.isfinite(value):
            raise DbInputError(f"{name}={value!r} is not a finite time in s")
        bound = float(value)
        where.append(
            SampleChunk.t_last_s >= bound if name == "from_s" else SampleChunk.t_first_s < bound
        )
    return where


_Chunk = tuple[int, int, pa.RecordBatch]
"""A decoded stored chunk: (trial id, first `seq`, batch of its stored schema)."""


def _joined(
    chunks: Sequence[_Chunk],
    seq_from: int | None,
    seq_to: int | None,
    from_s: float | None,
    to_s: float | None,
) -> pa.Table:
    """Chunks (of one schema) as one `span_schema` table, cut to `seq_from <= seq < seq_to`
    and `from_s <= t_s < to_s` (each bound applied when given); at least one chunk."""
    first = chunks[0][2].schema
    if any(batch.schema is not first and not batch.schema.equals(first) for *_, batch in chunks):
        raise DbInputError("samples of trials stored under different schemas in one span")
    schema = span_schema(first)
    counts = np.array([batch.num_rows for _, _, batch in chunks], dtype=np.int64)
    firsts = np.array([first for _, first, _ in chunks], dtype=np.int64)
    starts = np.cumsum(counts) - counts
    seq = np.arange(int(counts.sum()), dtype=np.int64) + np.repeat(firsts - starts, counts)
    trial_id = np.repeat(np.array([t for t, _, _ in chunks], dtype=np.int64), counts)
    stored = pa.Table.from_batches([batch for _, _, batch in chunks])
    table = pa.Table.from_arrays(
        [pa.array(trial_id), pa.array(seq), *stored.columns], schema=schema
    )
    keep = np.ones(len(seq), dtype=bool)
    if seq_from is not None:
        keep &= seq >= seq_from
    if seq_to is not None:
        keep &= seq < seq_to
    if from_s is not None or to_s is not None:
        t_s = stored.column("t_s").to_numpy()
        if from_s is not None:
            keep &= t_s >= from_s
        if to_s is not None:
            keep &= t_s < to_s
    return table if keep.all() else table.filter(pa.array(keep))


def _batched(items: Iterable[T], n: int) -> Iterator[list[T]]:
    """`items` in lists of at most `n` (itertools.batched from Python 3.12)."""
    group: list[T] = []
    for item in items:
        group.append(item)
        if len(group) == n:
            yield group
            group = []
    if group:
        yield group


def seq_ranges(engine: Engine, trial_ids: Iterable[int]) -> dict[int, tuple[int, int]]:
    """`{trial_id: (first seq, last seq)}` of the trials that have samples.

    Index look-ups on the chunks' key (`trial_id, first_seq`); no chunk is decoded.
    """
    ids = list(dict.fromkeys(int(i) for i in trial_ids))
    c = SampleChunk
    first = select(func.min(c.first_seq)).where(c.trial_id == Trial.id).scalar_subquery()
    last = (
        select(c.first_seq + c.n_samples - 1)
        .where(c.trial_id == Trial.id)
        .order_by(c.first_seq.desc())
        .limit(1)
        .scalar_subquery()
    )
    out: dict[int, tuple[int, int]] = {}
    with Session(engine) as session:
        for lo in range(0, len(ids), 500):
            rows = session.execute(
                select(Trial.id, first, last).where(Trial.id.in_(ids[lo : lo + 500]))
            )
            out.update({int(t): (int(a), int(b)) for t, a, b in rows if a is not None})
    return out


def schema_ids(engine: Engine, trial_ids: Iterable[int]) -> dict[int, int]:
    """`{trial_id: sample_schemas.id}` of the trials that have samples (a trial's chunks
    share the schema their writer was given)."""
    ids = list(dict.fromkeys(int(i) for i in trial_ids))
    c = SampleChunk
    out: dict[int, int] = {}
    with Session(engine) as session:
        for lo in range(0, len(ids), 500):
            rows = session.execute(
                select(c.trial_id, func.min(c.schema_id))
                .where(c.trial_id.in_(ids[lo : lo + 500]))
                .group_by(c.trial_id)
            )
            out.update({int(t): int(s) for t, s in rows})
    return out


def plan_spans(
    engine: Engine,
    trial_ids: Sequence[int],
    *,
    max_rows: int = SPAN_ROWS,
    join_trials: bool = True,
) -> list[list[SampleSpan]]:
    """The spans that read `trial_ids`' samples, one list per trial in the given order.

    A span holds at most `max_rows` samples. With `join_trials`, consecutive trials
    (ascending ids) of one stored schema whose samples fit share a span, listed under
    the first of them; the others get []. A trial without samples gets [].
    """
    if max_rows < 1:
        raise DbInputError(f"max_rows {max_rows!r} is not a positive number of rows")
    ranges = seq_ranges(engine, trial_ids)
    schemas = schema_ids(engine, trial_ids)
    plan: list[list[SampleSpan]] = [[] for _ in trial_ids]
    group: list[int] = []
    group_rows, group_at, group_schema = 0, 0, None
    for k, trial_id in enumerate(trial_ids):
        if trial_id not in ranges:
            continue
        first, last = ranges[trial_id]
        n = last - first + 1
        schema = schemas.get(trial_id)
        fits = (
            join_trials
            and group
            and trial_id > group[-1]
            and group_rows + n <= max_rows
            and schema == group_schema
        )
        if group and not fits:
            plan[group_at].append(SampleSpan(tuple(group), rows=group_rows, schema_id=group_schema))
            group = []
        if n > max_rows:
            plan[k] += [
                SampleSpan((trial_id,), lo, lo + max_rows, max_rows, schema)
                for lo in range(first, last + 1, max_rows)
            ]
            continue
        if not group:
            group_rows, group_at, group_schema = 0, k, schema
        group.append(trial_id)
        group_rows += n
    if group:
        plan[group_at].append(SampleSpan(tuple(group), rows=group_rows, schema_id=group_schema))
    return plan


def read_spans(
    engine: Engine,
    spans: Iterable[SampleSpan],
    work: Callable[[SampleSpan, pa.Table], T],
    *,
    workers: int = 1,
    from_s: float | None = None,
    to_s: float | None = None,
) -> Generator[T, None, None]:
    """`work(span, table)` for each span, in the spans' order, read by `workers` threads.

    Each thread reads with its own `SampleReader`; `work` runs in that thread too. At
    most `workers + 1` spans are read ahead of the one the caller is consuming. Closing
    the iterator early (or an error) cancels the spans not started and closes the
    connections.
    """
    if workers < 1:
        raise DbInputError(f"workers {workers!r} is not a positive number of threads")
    readers: list[SampleReader] = []
    lock = threading.Lock()
    local = threading.local()

    def run(span: SampleSpan) -> T:
        reader = getattr(local, "reader", None)
        if reader is None:
            reader = local.reader = SampleReader(engine)
            with lock:
                readers.append(reader)
        return work(span, reader.span(span, from_s=from_s, to_s=to_s))

    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="sample-reader")
    pending: deque[Future[T]] = deque()
    try:
        for span in spans:
            pending.append(pool.submit(run, span))
            if len(pending) > workers:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        for reader in readers:
            reader.close()
