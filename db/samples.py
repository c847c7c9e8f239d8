"""Trial sample streams: the write path (buffered, committed in chunks of at most a
second).

A crash mid-trial must lose at most `chunk_s` seconds of samples (one second by
default). What a crash loses is what the writer holds plus what the caller is computing
for its next call, so the writer commits by trial time, whatever the size of the steps
it is handed: a chunk never spans more than `chunk_s`, and after each call it commits
at once when waiting for one more step of the same length would put more than `chunk_s`
at risk (unpaced sessions handed 0.5 s steps, and committing only when the next
step arrived lost 1.5 s). Each chunk is one transaction; `flush`/`close` commit the rest.

A chunk is stored as one row of `sample_chunks`: its columns as one compressed Arrow
record batch (`db.sample_codec`), not a row per sample (binding a Python
value per sample held the writer well below a plain multi-row INSERT; a chunk is
one row whatever its length, so the writer's cost is the encoding). The columns handed
in are kept as arrays until the chunk is encoded; no Python object is built per sample.
The writer keeps one connection for its life (taken at the first chunk, given back at
`close` or after any failed commit), so a chunk costs its transaction, not also a
checkout from the pool and the reset on return.

Another program's lock (SQLite allows one writer at a time) need not stop a trial: with
`hold_s` > 0 a chunk that meets a lock is kept in memory and committed with the next one,
each attempt waiting only `LOCK_POLL_MS`, so the caller's loop goes on (and can show the
wait, `on_wait`) while up to `hold_s` of trial time is held; past that, or at `close`, the
writer waits for the lock (up to `hold_s` of wall time at `close`). No sample is dropped:
chunks are committed in order, or the error is raised.

Reading (Arrow record batches of bounded size, one trial or many in parallel) is
`db.sample_reader`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from types import TracebackType
from typing import Any

import numpy as np
import pyarrow as pa
from sqlalchemy import Connection, Engine, insert, select
from sqlalchemy.exc import IntegrityError, OperationalError

from db.errors import DbInputError
from db.models.trial import SampleChunk, SampleSchema
from db.sample_codec import (
    check_schema,
    column_array,
    encode,
    schema_bytes,
    schema_fingerprint,
)

__all__ = ["SampleWriter"]

LOCK_POLL_MS = 50
"""How long one commit attempt waits for another program's lock while samples are held."""


class SampleWriter:
    """Stream one trial's samples into `sample_chunks`, committing every `chunk_s` of trial time.

    Parameters
    ----------
    engine
        Engine of the study database.
    trial_id
        The trial the samples belong to (must exist).
    schema
        The chunks' Arrow schema: the trial's task's declared sample columns
        (`study.protocol.tasks.Task.sample_schema`, fields made by
        `db.sample_codec.sample_field`), `t_s` first.
    chunk_s
        Longest span of trial time, in s, held in memory before a commit; > 0.
    start_seq
        Sequence number of the first sample (continue a stream after a restart).
    hold_s
        Trial time, in s, of samples held in memory while another program holds the
        database's lock (0: each commit waits for the lock, up to the busy timeout).
    on_wait
        Called after each commit attempt while samples are held, with the seconds since
        the first attempt that met the lock and the samples held (None, 0 when it ends).

    Sample times must not decrease. Columns not given are stored as NULL.

    Examples
    --------
    >>> schema = get_task(trial.task).sample_schema()        # doctest: +SKIP
    >>> with SampleWriter(engine, trial.id, schema=schema) as out:  # doctest: +SKIP
    ...     out.append(t_s=0.001, proximal_force_n=0.12)
    """

    def __init__(
        self,
        engine: Engine,
        trial_id: int,
        *,
        schema: pa.Schema,
        chunk_s: float = 1.0,
        start_seq: int = 0,
        hold_s: float = 0.0,
        on_wait: Callable[[float | None, int], None] | None = None,
    ) -> None:
        if not chunk_s > 0:
            raise DbInputError(f"chunk_s {chunk_s!r} is not a positive duration in s")
        if not hold_s >= 0:
            raise DbInputError(f"hold_s {hold_s!r} is not a duration in s >= 0")
        self.schema = check_schema(schema)
        self._names: list[str] = self.schema.names
        self._name_set = frozenset(self._names)
        self._schema_id: int | None = None
        self.hold_s = hold_s
        self.on_wait = on_wait
        self._pending: list[dict[str, Any]] = []
        """Encoded chunks not yet committed (another program held the lock), in order."""
        self.waiting_since: float | None = None
        """time.monotonic() of the first commit attempt that met a lock, while one lasts."""
        self.engine = engine
        self._conn: Connection | None = None
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
        """Add one sample; `values` are columns of the schema other than `t_s`."""
        self.extend({"t_s": [t_s], **{k: [v] for k, v in values.items()}})

    def extend(self, columns: Mapping[str, Sequence[Any] | np.ndarray]) -> None:
        """Add samples given as equal-length columns named as in the schema."""
        names = self._names
        unknown = columns.keys() - self._name_set
        if unknown or "t_s" not in columns:
            raise DbInputError(
                f"sample columns {sorted(columns)} must include 't_s' and only names from {names}"
            )
        t = np.asarray(columns["t_s"], dtype=float)
        n = len(t)
        if n == 0:
            return
        self._check_times(t)
        given: list[pa.Array] = []
        for name in names:
            col = t if name == "t_s" else columns.get(name)
            if col is not None and len(col) != n:
                raise DbInputError(f"sample column {name!r} has {len(col)} values; expected {n}")
            given.append(column_array(name, col, n, self.schema))
        self._add_block(t, _Block(n, given))

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
            self._buffer.append(block if i == 0 and j == len(t) else block[i:j])
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
        """Commit the buffered samples as one transaction (held if another program has
        the lock and `hold_s` allows)."""
        self._chunk_start_t = None
        n = self._buffered()
        if n == 0:
            self._buffer.clear()
        else:
            self._pending.append(self._encode(n))
            self._buffer.clear()
        if self._pending:
            self._commit(wait=self.hold_s <= 0 or self._held_s() > self.hold_s)

    def _encode(self, n: int) -> dict[str, Any]:
        if len(self._buffer) == 1:  # one call's samples: its columns as they are
            columns = self._buffer[0].columns
        else:
            columns = [
                pa.concat_arrays([b.columns[k] for b in self._buffer])
                for k in range(len(self.schema))
            ]
        batch = pa.RecordBatch.from_arrays(columns, schema=self.schema)
        data, raw_bytes = encode(batch)
        t_s = batch.column(0)
        row = {
            "trial_id": self.trial_id,
            "first_seq": self.next_seq,
            "n_samples": n,
            "t_first_s": t_s[0].as_py(),
            "t_last_s": t_s[n - 1].as_py(),
            "raw_bytes": raw_bytes,
            "schema_id": self._stored_schema_id(),
            "data": data,
        }
        self.next_seq += n
        return row

    def _held_s(self) -> float:
        """Trial time of the chunks held uncommitted."""
        if not self._pending:
            return 0.0
        return self._pending[-1]["t_last_s"] - self._pending[0]["t_first_s"] + self._period_s

    def held_samples(self) -> int:
        return sum(r["n_samples"] for r in self._pending)

    def _commit(self, wait: bool) -> None:
        """Write the held chunks in one transaction. Not `wait`ing (SQLite), an attempt
        waits `LOCK_POLL_MS` for a lock and keeps the chunks if it is still held."""
        poll = not wait and self.engine.dialect.name == "sqlite"
        if self._conn is None:
            self._conn = self.engine.connect()
        conn = self._conn
        try:
            with conn.begin():
                if poll:
                    conn.exec_driver_sql(f"PRAGMA busy_timeout={LOCK_POLL_MS}")
                try:
                    for row in self._pending:
                        _write_chunk(conn, row)
                finally:
                    if poll:
                        from db.engine import busy_timeout_ms

                        ms = busy_timeout_ms(self.engine.url)
                        conn.exec_driver_sql(f"PRAGMA busy_timeout={ms}")
        except BaseException as exc:
            # a failed transaction gives its connection back (the next attempt takes a
            # fresh one: nothing of a broken connection is reused)
            self._release()
            if not isinstance(exc, OperationalError) or wait or not is_lock(exc):
                raise
            if self.waiting_since is None:
                self.waiting_since = time.monotonic()
            if self.on_wait is not None:
                self.on_wait(time.monotonic() - self.waiting_since, self.held_samples())
            return
        self.rows_committed += self.held_samples()
        self.chunks_committed += len(self._pending)
        self._pending.clear()
        if self.waiting_since is not None:
            self.waiting_since = None
            if self.on_wait is not None:
                self.on_wait(None, 0)

    def _stored_schema_id(self) -> int:
        """The id of the writer's schema in `sample_schemas`, stored on first use."""
        if self._schema_id is None:
            self._schema_id = stored_schema_id(self.engine, self.schema)
        return self._schema_id

    def _release(self) -> None:
        """Give the writer's connection back to the pool (taken again when needed)."""
        conn, self._conn = self._conn, None
        if conn is not None:
            conn.close()

    def close(self) -> None:
        """Commit everything: held chunks wait for the lock up to `hold_s` of wall time."""
        try:
            self.flush()
            end = time.monotonic() + self.hold_s
            while self._pending:
                last = time.monotonic() >= end
                self._commit(wait=last)
                if self._pending:
                    time.sleep(LOCK_POLL_MS / 1000)
        finally:
            self._release()

    def __enter__(self) -> SampleWriter:
        # the schema's row before the first sample: a chunk encoded while another program
        # holds the lock must not need a write of its own
        self._stored_schema_id()
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
            self.close()
            return
        try:
            self.close()
        except Exception:  # the original exception propagates
            self._buffer.clear()
            self._pending.clear()


def stored_schema_id(engine: Engine, schema: pa.Schema) -> int:
    """The id of `schema` in `sample_schemas`, inserted if it is not there yet (another
    writer inserting the same schema at once is found on the second look)."""
    data = schema_bytes(schema)
    key = schema_fingerprint(data)
    query = select(SampleSchema.id).where(SampleSchema.fingerprint == key)
    try:
        with engine.begin() as conn:
            found = conn.execute(query).scalar()
            if found is not None:
                return int(found)
            conn.execute(insert(SampleSchema).values(fingerprint=key, data=data))
            return int(conn.execute(query).scalar_one())
    except IntegrityError:  # inserted by another writer since the look
        with engine.connect() as conn:
            return int(conn.execute(query).scalar_one())


class _Block:
    """Samples handed in one call, held as Arrow columns in the schema's order (all
    NULL for a column not given) so that no object is built per sample."""

    __slots__ = ("columns", "n")

    def __init__(self, n: int, columns: list[pa.Array]) -> None:
        self.n = n
        self.columns = columns

    def __getitem__(self, rows: slice) -> _Block:
        lo, hi, _ = rows.indices(self.n)
        return _Block(max(hi - lo, 0), [c.slice(lo, max(hi - lo, 0)) for c in self.columns])


def is_lock(exc: OperationalError) -> bool:
    """Another program holds the database's lock (not a full disk, not a lost file)."""
    return "locked" in str(exc.orig if exc.orig is not None else exc).lower()


def _write_chunk(conn: Connection, row: dict[str, Any]) -> None:
    """Insert one chunk's row of `sample_chunks` (its own function: the write that a full
    disk makes fail)."""
    conn.execute(insert(SampleChunk), row)
