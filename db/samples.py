"""The write path for trial sample streams: buffered, committed in chunks of at most a second.

A crash mid-trial must lose at most the samples since the last commit, so the writer
commits whenever the buffered samples would span `chunk_s` seconds of trial time (one
second by default) and on `flush`/`close`. Each chunk is one transaction.

The rows go to the DBAPI cursor rather than through ORM objects or an `Insert` with a
list of dicts: a dict per row is what holds SQLAlchemy's executemany well below the
200,000 rows/s target (`study bench db`). On SQLite one multi-row `INSERT ... VALUES
(...), (...)` per few hundred rows beats `executemany` by about half again, because
SQLite steps one statement instead of re-binding one per row; PostgreSQL takes
`COPY ... FROM STDIN`, psycopg's bulk path.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import Any

import numpy as np
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
        self._buffer: list[np.ndarray] = []
        self._chunk_start_t: float | None = None
        self._last_t = -np.inf

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
        block = np.empty((n, len(SAMPLE_COLUMNS)), dtype=object)
        for k, name in enumerate(SAMPLE_COLUMNS):
            col = columns.get(name)
            if col is None:
                block[:, k] = None
            elif len(col) != n:
                raise DbInputError(f"sample column {name!r} has {len(col)} values; expected {n}")
            else:
                # An object array stores Python floats/ints/str, which every driver binds.
                block[:, k] = col
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
        return sum(len(b) for b in self._buffer)

    def _add_block(self, t: np.ndarray, block: np.ndarray) -> None:
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

    def flush(self) -> None:
        """Commit the buffered samples as one transaction."""
        self._chunk_start_t = None
        n = self._buffered()
        if n == 0:
            self._buffer.clear()
            return
        rows = np.empty((n, len(_ALL_COLUMNS)), dtype=object)
        rows[:, 0] = self.trial_id
        rows[:, 1] = range(self.next_seq, self.next_seq + n)
        rows[:, 2:] = np.concatenate(self._buffer)
        with self.engine.begin() as conn:
            _write_rows(conn, rows)
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
        # Whatever ended the trial, keep what was measured.
        self.flush()


def _write_rows(conn: Connection, rows: np.ndarray) -> None:
    cursor = conn.connection.cursor()
    try:
        if is_sqlite(conn):
            for lo in range(0, len(rows), _ROWS_PER_STATEMENT):
                part = rows[lo : lo + _ROWS_PER_STATEMENT]
                full = len(part) == _ROWS_PER_STATEMENT
                cursor.execute(
                    _FULL_INSERT_SQL if full else _insert_sql(len(part)), part.ravel().tolist()
                )
        else:
            with cursor.copy(_COPY_SQL) as copy:
                for row in rows.tolist():
                    copy.write_row(row)
    finally:
        cursor.close()
