"""Trial sample streams: the write path (buffered, committed in chunks of at most a
second) and the read path (Arrow record batches of bounded size).

A crash mid-trial must lose at most `chunk_s` seconds of samples (one second by
default). What a crash loses is what the writer holds plus what the caller is computing
for its next call, so the writer commits by trial time, whatever the size of the steps
it is handed: a chunk never spans more than `chunk_s`, and after each call it commits
at once when waiting for one more step of the same length would put more than `chunk_s`
at risk (issue 18: unpaced sessions hand 0.5 s steps, and committing only when the next
step arrived lost 1.5 s). Each chunk is one transaction; `flush`/`close` commit the rest.

The rows go to the DBAPI cursor rather than through ORM objects or an `Insert` with a
list of dicts: a dict per row is what holds SQLAlchemy's executemany well below the
200,000 rows/s target (`study bench db`). On SQLite one multi-row `INSERT ... VALUES
(...), (...)` per few hundred rows beats `executemany` by about half again, because
SQLite steps one statement instead of re-binding one per row; PostgreSQL takes
`COPY ... FROM STDIN`, psycopg's bulk path.

Reading goes through ADBC (Apache Arrow's database connectivity: `adbc-driver-sqlite`,
`adbc-driver-postgresql`), which hands over Arrow record batches of a bounded number of
rows. A DBAPI cursor builds a Python tuple and a float object per value: on the demo
study that is 2.8 s of CPU per million samples against 1.2 s for ADBC, and the
export target is a million samples per second. `SampleReader` reads one trial at a
time, in `seq` order, through the primary key's index, so memory stays at one batch
whatever the size of the study. On PostgreSQL the driver streams each query with
`COPY ... TO STDOUT (FORMAT binary)`. The SQLite driver infers a column's Arrow type
from the values of the first batch and refuses a later batch that disagrees (a
column that starts NULL would become int64); every query therefore starts with one
typed row (`seq = -1`) that the reader drops.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from itertools import chain
from types import TracebackType
from typing import Any

import numpy as np
import pyarrow as pa
from sqlalchemy import Connection, Engine

from db.engine import is_sqlite
from db.errors import DbInputError
from db.models.trial import SAMPLE_COLUMNS

_ALL_COLUMNS = ("trial_id", "seq", *SAMPLE_COLUMNS)
_ROWS_PER_STATEMENT = 500
"""Rows per multi-row INSERT on SQLite (7,000 parameters; SQLite allows 32,766 or more)."""
_COPY_SQL = f"COPY samples ({', '.join(_ALL_COLUMNS)}) FROM STDIN"


def _insert_sql(rows: int) -> str:
    one = "(" + ", ".join("?" for _ in _ALL_COLUMNS) + ")"
    return f"INSERT INTO samples ({', '.join(_ALL_COLUMNS)}) VALUES " + ", ".join([one] * rows)


_FULL_INSERT_SQL = _insert_sql(_ROWS_PER_STATEMENT)


class SampleWriter:
    """Stream one trial's samples into `samples`, committing every `chunk_s` of trial time.

    Parameters
    ----------
    engine
        Engine of the study database.
    trial_id
        The trial the samples belong to (must exist).
    chunk_s
        Longest span of trial time, in s, held in memory before a commit; > 0.
    start_seq
        Sequence number of the first sample (continue a stream after a restart).

    Sample times must not decrease. Columns not given are stored as NULL.

    Examples
    --------
    >>> with SampleWriter(engine, trial.id) as out:          # doctest: +SKIP
    ...     out.append(t_s=0.001, proximal_force_n=0.12)
    """

    def __init__(
        self, engine: Engine, trial_id: int, *, chunk_s: float = 1.0, start_seq: int = 0
    ) -> None:
        if not chunk_s > 0:
            raise DbInputError(f"chunk_s {chunk_s!r} is not a positive duration in s")
        self.engine = engine
        self.trial_id = trial_id
        self.chunk_s = chunk_s
        self.next_seq = start_seq
        self.rows_committed = 0
        self.chunks_committed = 0
        self._buffer: list[_Block] = []
        self._chunk_start_t: float | None = None
        self._last_t = -np.inf
        self._period_s = 0.0
        """Latest positive spacing of sample times: the span one held sample stands for."""

    def append(self, t_s: float, **values: Any) -> None:
        """Add one sample; `values` are columns of `SAMPLE_COLUMNS` other than `t_s`."""
        self.extend({"t_s": [t_s], **{k: [v] for k, v in values.items()}})

    def extend(self, columns: Mapping[str, Sequence[Any] | np.ndarray]) -> None:
        """Add samples given as equal-length columns named as in `SAMPLE_COLUMNS`."""
        unknown = set(columns) - set(SAMPLE_COLUMNS)
        if unknown or "t_s" not in columns:
            raise DbInputError(
                f"sample columns {sorted(columns)} must include 't_s' and only names "
                f"from {list(SAMPLE_COLUMNS)}"
            )
        t = np.asarray(columns["t_s"], dtype=float)
        n = len(t)
        if n == 0:
            return
        self._check_times(t)
        given: list[list[Any] | None] = []
        for name in SAMPLE_COLUMNS:
            col = columns.get(name)
            if col is not None and len(col) != n:
                raise DbInputError(f"sample column {name!r} has {len(col)} values; expected {n}")
            # .tolist() gives Python floats/ints/str, which every driver binds, in one C
            # call per column instead of one object per value
            given.append(None if col is None else np.asarray(col).tolist())
        block = _Block(n, given)
        self._add_block(t, block)

    def _check_times(self, t: np.ndarray) -> None:
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size:
            raise DbInputError(
                f"sample time t_s={t[bad[0]]} at sample {self.next_seq + self._buffered() + bad[0]}"
                " is not a finite number of seconds"
            )
        back = np.flatnonzero(np.diff(np.concatenate(([self._last_t], t))) < 0)
        if back.size:
            i = back[0]
            raise DbInputError(
                f"sample time t_s={t[i]} at sample {self.next_seq + self._buffered() + i} "
                "goes back in time; expected non-decreasing times"
            )

    def _buffered(self) -> int:
        return sum(b.n for b in self._buffer)

    def _add_block(self, t: np.ndarray, block: _Block) -> None:
        before_t = self._last_t
        steps = np.diff(np.concatenate(([before_t], t)) if np.isfinite(before_t) else t)
        if (steps > 0).any():
            self._period_s = float(steps[steps > 0][-1])
        i = 0
        while i < len(t):
            if self._chunk_start_t is None:
                self._chunk_start_t = float(t[i])
            # Samples before chunk_start + chunk_s belong to the current chunk.
            j = int(np.searchsorted(t, self._chunk_start_t + self.chunk_s, side="left"))
            j = max(j, i)
            self._buffer.append(block[i:j])
            self._last_t = float(t[j - 1]) if j > i else self._last_t
            if j < len(t):
                self.flush()
            i = j
        # Commit ahead: the next call will likely hand as much trial time as this one.
        if self._chunk_start_t is not None:
            handed_s = float(t[-1] - (before_t if np.isfinite(before_t) else t[0]))
            held_s = self._last_t - self._chunk_start_t + self._period_s
            if held_s + max(handed_s, self._period_s) > self.chunk_s + 1e-9:
                self.flush()

    def flush(self) -> None:
        """Commit the buffered samples as one transaction."""
        self._chunk_start_t = None
        n = self._buffered()
        if n == 0:
            self._buffer.clear()
            return
        columns: list[Sequence[Any]] = [
            [self.trial_id] * n,
            range(self.next_seq, self.next_seq + n),
        ]
        for k in range(len(SAMPLE_COLUMNS)):
            values: list[Any] = []
            for b in self._buffer:
                given = b.columns[k]
                values += [None] * b.n if given is None else given
            columns.append(values)
        with self.engine.begin() as conn:
            _write_rows(conn, columns, n)
        self.next_seq += n
        self.rows_committed += n
        self.chunks_committed += 1
        self._buffer.clear()

    def close(self) -> None:
        self.flush()

    def __enter__(self) -> SampleWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        # Whatever ended the trial, keep what was measured; if the database is what
        # failed (a full disk), the first error is the one to report, not a second.
        if exc_type is None:
            self.flush()
            return
        try:
            self.flush()
        except Exception:  # noqa: BLE001 - the original exception propagates
            self._buffer.clear()


class _Block:
    """Samples handed in one call, held as columns (a Python list per column, None for a
    column not given) so that no object is built per row."""

    __slots__ = ("columns", "n")

    def __init__(self, n: int, columns: list[list[Any] | None]) -> None:
        self.n = n
        self.columns = columns

    def __getitem__(self, rows: slice) -> _Block:
        lo, hi, _ = rows.indices(self.n)
        return _Block(max(hi - lo, 0), [None if c is None else c[rows] for c in self.columns])


def _write_rows(conn: Connection, columns: list[Sequence[Any]], n: int) -> None:
    """Insert `n` rows given as columns in `_ALL_COLUMNS` order."""
    cursor = conn.connection.cursor()
    try:
        if is_sqlite(conn):
            for lo in range(0, n, _ROWS_PER_STATEMENT):
                hi = min(lo + _ROWS_PER_STATEMENT, n)
                # row-major parameters straight from the columns: zip pairs them in C
                params = list(chain.from_iterable(zip(*(c[lo:hi] for c in columns))))
                full = hi - lo == _ROWS_PER_STATEMENT
                cursor.execute(_FULL_INSERT_SQL if full else _insert_sql(hi - lo), params)
        else:
            with cursor.copy(_COPY_SQL) as copy:
                for row in zip(*columns):
                    copy.write_row(row)
    finally:
        cursor.close()


SAMPLE_SCHEMA = pa.schema(
    [
        ("seq", pa.int64()),
        *((name, pa.string() if name == "branch" else pa.float64()) for name in SAMPLE_COLUMNS),
    ]
)
"""Arrow schema of the batches `SampleReader` yields: `seq`, then `SAMPLE_COLUMNS`."""

_BATCH_ROWS = 65_536


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

    Use as a context manager; one reader serves any number of `trial` calls.
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
        else:
            import adbc_driver_postgresql.dbapi

            libpq = url.set(drivername="postgresql").render_as_string(hide_password=False)
            self._conn = adbc_driver_postgresql.dbapi.connect(libpq)

    def trial(
        self, trial_id: int, *, from_s: float | None = None, to_s: float | None = None
    ) -> Iterator[pa.RecordBatch]:
        """The samples of one trial in `seq` order, with `from_s <= t_s < to_s` when given."""
        sql = self._query(int(trial_id), from_s, to_s)
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
                    if batch.num_rows == 0 or batch.column(0)[0].as_py() != -1:
                        raise RuntimeError("the SQLite sample query lost its typed first row")
                    batch = batch.slice(1)
                first = False
                # The PostgreSQL driver's bound is in bytes: slice to the row bound too.
                for lo in range(0, batch.num_rows, self.batch_rows):
                    yield _conform(batch.slice(lo, self.batch_rows))
        finally:
            cursor.close()

    def _query(self, trial_id: int, from_s: float | None, to_s: float | None) -> str:
        where = [f"trial_id = {trial_id}"]
        for name, op, value in (("from_s", ">=", from_s), ("to_s", "<", to_s)):
            if value is None:
                continue
            if not math.isfinite(value):
                raise DbInputError(f"{name}={value!r} is not a finite time in s")
            where.append(f"t_s {op} {float(value)!r}")
        columns = ", ".join(SAMPLE_SCHEMA.names)
        body = (
            f"SELECT {columns} FROM samples WHERE {' AND '.join(where)} ORDER BY seq"
        )
        if not self._sqlite:
            return body
        typed = ", ".join(
            f"{'-1' if f.name == 'seq' else repr('') if f.name == 'branch' else '0.5'} AS {f.name}"
            for f in SAMPLE_SCHEMA
        )
        return f"SELECT {typed} UNION ALL SELECT * FROM ({body})"

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> SampleReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _conform(batch: pa.RecordBatch) -> pa.RecordBatch:
    """`batch` with exactly `SAMPLE_SCHEMA`'s types (the drivers may give null-typed columns)."""
    if batch.schema.equals(SAMPLE_SCHEMA):
        return batch
    return pa.RecordBatch.from_arrays(
        [batch.column(i).cast(f.type) for i, f in enumerate(SAMPLE_SCHEMA)],
        schema=SAMPLE_SCHEMA,
    )
