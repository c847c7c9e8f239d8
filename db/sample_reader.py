"""Reading trials' sample streams as Arrow record batches in bounded memory: one trial,
or many trials in spans read by a pool of threads and handed back in order.

Reading goes through ADBC (Apache Arrow's database connectivity: `adbc-driver-sqlite`,
`adbc-driver-postgresql`), which hands over Arrow record batches of a bounded number of
rows. A DBAPI cursor builds a Python tuple and a float object per value: on the demo
study that is 2.8 s of CPU per million samples against 1.2 s for ADBC. On PostgreSQL
the driver streams each query with `COPY ... TO STDOUT (FORMAT binary)`. The SQLite
driver infers a column's Arrow type from the values of the first batch and refuses a
later batch that disagrees (a column that starts NULL would become int64); every query
therefore starts with one typed row (`seq = -1`) that the reader drops.

Reading many trials (`study export --samples`, issue 26). Measured on the 10,000,000
samples of `study bench export` (SQLite), the ADBC driver spends about 1.1 us of CPU
per sample of 14 columns: about half in SQLite itself (decoding the record, the
primary key's index), half in the driver's per-value calls (`sqlite3_column_*`, a
nanoarrow append, a mutex). One thread therefore reads at most about 0.9 million
samples per CPU-second whatever is done around it, below the export target of a
million a second. Both drivers and pyarrow release the GIL while they read, so
`read_spans` reads with several threads, each with its own connection, and hands the
results back in order:

- `plan_spans` cuts the trials into spans of at most `max_rows` samples: consecutive
  small trials together (one query for many of them, `ORDER BY trial_id, seq` through
  the primary key's index), a long trial in windows of `seq`. A span's size is known
  before it is read (from each trial's first and last `seq`, two index look-ups), so
  memory is bounded by construction, however the samples are spread over the trials.
- `read_spans` keeps at most `workers + 1` spans in flight and runs the caller's
  function on each span in the worker thread (building key columns, formatting CSV),
  so that the calling thread only writes.

Python's concurrent.futures does the pool; what is written here is the bounded,
ordered hand-back, which it does not offer (`Executor.map` submits every item at once).
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import TypeVar

import pyarrow as pa
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session

from db.engine import busy_timeout_ms, is_sqlite
from db.errors import DbInputError
from db.models.trial import SAMPLE_COLUMNS, Sample, Trial

SAMPLE_SCHEMA = pa.schema(
    [
        ("seq", pa.int64()),
        *((name, pa.string() if name == "branch" else pa.float64()) for name in SAMPLE_COLUMNS),
    ]
)
"""Arrow schema of the batches `SampleReader.trial` yields: `seq`, then `SAMPLE_COLUMNS`."""
SPAN_SCHEMA = pa.schema([("trial_id", pa.int64()), *SAMPLE_SCHEMA])
"""Arrow schema of a span's table: `trial_id`, then `SAMPLE_SCHEMA`."""

_BATCH_ROWS = 65_536
SPAN_ROWS = 65_536
"""Default most samples in one span (about 7 MB as Arrow columns)."""

_TYPED = {"trial_id": "-1", "seq": "-1", "branch": "''"}
"""Values of the typed first row of an SQLite query (0.5 for the float columns)."""

T = TypeVar("T")


@dataclass(frozen=True)
class SampleSpan:
    """Samples read by one query: whole trials, or a window of `seq` of one trial."""

    trial_ids: tuple[int, ...]
    """Trials in ascending id order (one when the span is a window)."""
    seq_from: int | None = None
    """First `seq` of the window (inclusive); None for whole trials."""
    seq_to: int | None = None
    """End of the window (exclusive); None for whole trials."""
    rows: int = 0
    """Most samples the span can hold (from the trials' first and last `seq`)."""


class SampleReader:
    """Read trials' sample streams as Arrow record batches of at most `batch_rows` rows.

    Parameters
    ----------
    engine
        Engine of the study database (an SQLite file or PostgreSQL; the reader opens
        its own ADBC connection to the same database).
    batch_rows
        Most rows in one batch, > 0. Memory held by the reader is about
        `batch_rows` x 100 bytes.

    Use as a context manager; one reader serves any number of `trial` or `span` calls
    from one thread at a time.
    """

    def __init__(self, engine: Engine, *, batch_rows: int = _BATCH_ROWS) -> None:
        if batch_rows < 1:
            raise DbInputError(f"batch_rows {batch_rows!r} is not a positive number of rows")
        self.batch_rows = batch_rows
        self._sqlite = is_sqlite(engine)
        url = engine.url
        if self._sqlite:
            import adbc_driver_sqlite.dbapi

            if url.database in (None, "", ":memory:"):
                raise DbInputError(
                    "an in-memory SQLite database cannot be read by a second connection; "
                    "expected an SQLite file"
                )
            self._conn = adbc_driver_sqlite.dbapi.connect(url.database)
            # Wait for a lock as the study's own connections do (`?timeout=S`, 30 s): a
            # connection opening while another recovers the WAL index got "database is
            # locked" at once (the driver's default is not to wait), seen with two reader
            # threads opening together.
            cursor = self._conn.cursor()
            try:
                cursor.execute(f"PRAGMA busy_timeout = {busy_timeout_ms(url)}")
                cursor.fetchall()
            finally:
                cursor.close()
        else:
            import adbc_driver_postgresql.dbapi

            libpq = url.set(drivername="postgresql").render_as_string(hide_password=False)
            self._conn = adbc_driver_postgresql.dbapi.connect(libpq)

    def trial(
        self, trial_id: int, *, from_s: float | None = None, to_s: float | None = None
    ) -> Iterator[pa.RecordBatch]:
        """The samples of one trial in `seq` order, with `from_s <= t_s < to_s` when given."""
        where = [f"trial_id = {int(trial_id)}", *_time_range(from_s, to_s)]
        yield from self._batches(SAMPLE_SCHEMA, where, "seq")

    def span(
        self, span: SampleSpan, *, from_s: float | None = None, to_s: float | None = None
    ) -> pa.Table:
        """A span's samples (`SPAN_SCHEMA`) in trial and `seq` order, `from_s <= t_s < to_s`."""
        where = [f"trial_id IN ({', '.join(str(int(i)) for i in span.trial_ids)})"]
        if span.seq_from is not None:
            where.append(f"seq >= {int(span.seq_from)}")
        if span.seq_to is not None:
            where.append(f"seq < {int(span.seq_to)}")
        where += _time_range(from_s, to_s)
        batches = list(self._batches(SPAN_SCHEMA, where, "trial_id, seq"))
        return pa.Table.from_batches(batches, schema=SPAN_SCHEMA)

    def _batches(self, schema: pa.Schema, where: list[str], order: str) -> Iterator[pa.RecordBatch]:
        sql = self._query(schema, where, order)
        cursor = self._conn.cursor()
        try:
            if self._sqlite:
                cursor.adbc_statement.set_options(
                    **{"adbc.sqlite.query.batch_rows": str(self.batch_rows)}
                )
            else:
                # The driver's hint is in bytes; about 100 bytes a sample.
                cursor.adbc_statement.set_options(
                    **{"adbc.postgresql.batch_size_hint_bytes": str(self.batch_rows * 100)}
                )
            cursor.execute(sql)
            first = True
            for batch in cursor.fetch_record_batch():
                if first and self._sqlite:
                    seq = batch.column(schema.get_field_index("seq"))
                    if batch.num_rows == 0 or seq[0].as_py() != -1:
                        raise RuntimeError("the SQLite sample query lost its typed first row")
                    batch = batch.slice(1)
                first = False
                # The PostgreSQL driver's bound is in bytes: slice to the row bound too.
                for lo in range(0, batch.num_rows, self.batch_rows):
                    yield _conform(batch.slice(lo, self.batch_rows), schema)
        finally:
            cursor.close()

    def _query(self, schema: pa.Schema, where: list[str], order: str) -> str:
        columns = ", ".join(schema.names)
        body = f"SELECT {columns} FROM samples WHERE {' AND '.join(where)} ORDER BY {order}"
        if not self._sqlite:
            return body
        typed = ", ".join(f"{_TYPED.get(f.name, '0.5')} AS {f.name}" for f in schema)
        return f"SELECT {typed} UNION ALL SELECT * FROM ({body})"

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> SampleReader:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _time_range(from_s: float | None, to_s: float | None) -> list[str]:
    where = []
    for name, op, value in (("from_s", ">=", from_s), ("to_s", "<", to_s)):
        if value is None:
            continue
        if not math.isfinite(value):
            raise DbInputError(f"{name}={value!r} is not a finite time in s")
        where.append(f"t_s {op} {float(value)!r}")
    return where


def _conform(batch: pa.RecordBatch, schema: pa.Schema) -> pa.RecordBatch:
    """`batch` with exactly `schema`'s types (the drivers may give null-typed columns)."""
    if batch.schema.equals(schema):
        return batch
    return pa.RecordBatch.from_arrays(
        [batch.column(i).cast(f.type) for i, f in enumerate(schema)], schema=schema
    )


def seq_ranges(engine: Engine, trial_ids: Iterable[int]) -> dict[int, tuple[int, int]]:
    """`{trial_id: (first seq, last seq)}` of the trials that have samples.

    Two index look-ups per trial (`min`/`max` of `seq` for one `trial_id`, which both
    databases answer from the primary key's index), not a scan of the samples.
    """
    ids = list(dict.fromkeys(int(i) for i in trial_ids))
    first = select(func.min(Sample.seq)).where(Sample.trial_id == Trial.id).scalar_subquery()
    last = select(func.max(Sample.seq)).where(Sample.trial_id == Trial.id).scalar_subquery()
    out: dict[int, tuple[int, int]] = {}
    with Session(engine) as session:
        for lo in range(0, len(ids), 500):
            rows = session.execute(
                select(Trial.id, first, last).where(Trial.id.in_(ids[lo : lo + 500]))
            )
            out.update({int(t): (int(a), int(b)) for t, a, b in rows if a is not None})
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
    (ascending ids) whose samples fit share a span, listed under the first of them;
    the others get []. A trial without samples gets [].
    """
    if max_rows < 1:
        raise DbInputError(f"max_rows {max_rows!r} is not a positive number of rows")
    ranges = seq_ranges(engine, trial_ids)
    plan: list[list[SampleSpan]] = [[] for _ in trial_ids]
    group: list[int] = []
    group_rows, group_at = 0, 0
    for k, trial_id in enumerate(trial_ids):
        if trial_id not in ranges:
            continue
        first, last = ranges[trial_id]
        n = last - first + 1
        fits = join_trials and group and trial_id > group[-1] and group_rows + n <= max_rows
        if group and not fits:
            plan[group_at].append(SampleSpan(tuple(group), rows=group_rows))
            group = []
        if n > max_rows:
            plan[k] += [
                SampleSpan((trial_id,), lo, lo + max_rows, max_rows)
                for lo in range(first, last + 1, max_rows)
            ]
            continue
        if not group:
            group_rows, group_at = 0, k
        group.append(trial_id)
        group_rows += n
    if group:
        plan[group_at].append(SampleSpan(tuple(group), rows=group_rows))
    return plan


def read_spans(
    engine: Engine,
    spans: Iterable[SampleSpan],
    work: Callable[[SampleSpan, pa.Table], T],
    *,
    workers: int = 1,
    from_s: float | None = None,
    to_s: float | None = None,
) -> Iterator[T]:
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
