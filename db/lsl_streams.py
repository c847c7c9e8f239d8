"""External streams' samples: write and read `lsl_streams` / `lsl_chunks`.

Each chunk is a zstd-compressed Arrow IPC stream (schema included: every stream has its
own channels) of `t_s` (time on the trial's clock), `lsl_time_s` (the source's own
stamp) and one column per channel under the stream's channel names, float64 for a
numeric stream and utf8 for a string one. In Python: `pyarrow.ipc.open_stream(
pyarrow.decompress(data, raw_bytes, codec="zstd")).read_all()`. pyarrow encodes,
compresses and decodes; this module only says which columns go where.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa
from sqlalchemy import Engine, insert, select, update
from sqlalchemy.orm import Session

from db.models.lsl import LslChunk, LslStream

CODEC = "zstd"
TIME_COLUMNS = ("t_s", "lsl_time_s")


def channel_names(labels: Sequence[str | None], n: int) -> list[str]:
    """Column names for a stream's `n` channels: its labels, `ch1`... where a label is
    missing, a suffix where one repeats or would clash with the time columns."""
    out: list[str] = []
    for k in range(n):
        label = (labels[k] if k < len(labels) else None) or f"ch{k + 1}"
        name, i = label, 2
        while name in out or name in TIME_COLUMNS:
            name, i = f"{label}_{i}", i + 1
        out.append(name)
    return out


@dataclass
class StreamMeta:
    """What `lsl_streams` holds of a stream, before its samples."""

    name: str
    type: str
    channel_format: str
    nominal_srate_hz: float
    channels: list[dict[str, str]]
    """[{"name", "unit", "type"}], names unique (`channel_names`)."""
    lsl_t0_s: float
    time_correction_s: float
    clock_rate: float = 1.0
    source_id: str = ""
    hostname: str = ""
    origin: str = "live"

    @property
    def is_string(self) -> bool:
        return self.channel_format == "string"

    def schema(self) -> pa.Schema:
        kind = pa.string() if self.is_string else pa.float64()
        return pa.schema(
            [pa.field("t_s", pa.float64(), False), pa.field("lsl_time_s", pa.float64(), False)]
            + [pa.field(c["name"], kind) for c in self.channels]
        )


@dataclass
class StreamWriter:
    """Append one stream's samples of one trial; each `write` is one committed chunk."""

    engine: Engine
    stream_id: int
    meta: StreamMeta
    next_seq: int = 0
    gaps: list[list[float]] = field(default_factory=list)

    @classmethod
    def create(cls, engine: Engine, trial_id: int, meta: StreamMeta) -> StreamWriter:
        with engine.begin() as conn:
            stream_id = conn.execute(
                insert(LslStream).returning(LslStream.id),
                {"trial_id": trial_id, "gaps": [], "n_samples": 0, **stream_row(meta)},
            ).scalar_one()
        return cls(engine, stream_id, meta)

    def trial_time(self, lsl_time_s: np.ndarray) -> np.ndarray:
        """The trial's clock of source stamps: (stamp + correction - t0) * rate."""
        m = self.meta
        return (lsl_time_s + m.time_correction_s - m.lsl_t0_s) * m.clock_rate

    def write(self, lsl_time_s: np.ndarray, values: Any, t_s: np.ndarray | None = None) -> None:
        """Commit `values` (n x channels) stamped `lsl_time_s` (the source's clock) as
        one chunk; `t_s` overrides their trial times (default `trial_time`)."""
        lsl_time_s = np.asarray(lsl_time_s, dtype=np.float64)
        if len(lsl_time_s) == 0:
            return
        t = self.trial_time(lsl_time_s) if t_s is None else t_s
        row = encode_chunk(self.meta, lsl_time_s, values, t)
        with self.engine.begin() as conn:
            conn.execute(
                insert(LslChunk), {"stream_id": self.stream_id, "first_seq": self.next_seq, **row}
            )
            conn.execute(
                update(LslStream)
                .where(LslStream.id == self.stream_id)
                .values(n_samples=LslStream.n_samples + row["n_samples"])
            )
        self.next_seq += row["n_samples"]

    def close(self, gaps: Sequence[Sequence[float]] = ()) -> None:
        """Record the stream's gaps (trial times, s) and its final time correction."""
        self.gaps = [[float(a), float(b)] for a, b in gaps]
        with self.engine.begin() as conn:
            conn.execute(
                update(LslStream)
                .where(LslStream.id == self.stream_id)
                .values(gaps=self.gaps, time_correction_s=self.meta.time_correction_s)
            )


def encode_chunk(
    meta: StreamMeta, lsl_time_s: np.ndarray, values: Any, t_s: np.ndarray
) -> dict[str, Any]:
    """The `lsl_chunks` columns (all but the key) of samples `values` (n x channels)."""
    n = len(lsl_time_s)
    t = np.asarray(t_s, dtype=np.float64)
    schema = meta.schema()
    if meta.is_string:
        cols = [pa.array([str(row[k]) for row in values]) for k in range(len(schema) - 2)]
    else:
        arr = np.asarray(values, dtype=np.float64).reshape(n, len(schema) - 2)
        cols = [pa.array(arr[:, k]) for k in range(arr.shape[1])]
    batch = pa.RecordBatch.from_arrays(
        [pa.array(t), pa.array(np.asarray(lsl_time_s, dtype=np.float64)), *cols], schema=schema
    )
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, schema) as out:
        out.write_batch(batch)
    raw = sink.getvalue()
    return {
        "n_samples": n,
        "t_first_s": float(t[0]),
        "t_last_s": float(t[-1]),
        "raw_bytes": raw.size,
        "data": pa.compress(raw, codec=CODEC, asbytes=True),
    }


def stream_row(meta: StreamMeta) -> dict[str, Any]:
    """The `lsl_streams` columns a stream's `meta` gives."""
    return {
        "name": meta.name,
        "type": meta.type,
        "source_id": meta.source_id,
        "hostname": meta.hostname,
        "channel_format": meta.channel_format,
        "nominal_srate_hz": float(meta.nominal_srate_hz),
        "channels": meta.channels,
        "lsl_t0_s": float(meta.lsl_t0_s),
        "time_correction_s": float(meta.time_correction_s),
        "clock_rate": float(meta.clock_rate),
        "origin": meta.origin,
    }


def decode_chunk(data: bytes, raw_bytes: int) -> pa.Table:
    """The samples of one stored chunk (see the module docstring)."""
    buf = pa.decompress(data, decompressed_size=raw_bytes, codec=CODEC)
    return pa.ipc.open_stream(buf).read_all()


def read_stream(engine: Engine, stream_id: int) -> pa.Table:
    """Every sample of one stored stream, in order (empty table with no samples)."""
    with Session(engine) as session:
        stream = session.get_one(LslStream, stream_id)
        meta = StreamMeta(
            stream.name,
            stream.type,
            stream.channel_format,
            stream.nominal_srate_hz,
            stream.channels,
            stream.lsl_t0_s,
            stream.time_correction_s,
        )
        chunks = session.execute(
            select(LslChunk.data, LslChunk.raw_bytes)
            .where(LslChunk.stream_id == stream_id)
            .order_by(LslChunk.first_seq)
        ).all()
    tables = [decode_chunk(d, r) for d, r in chunks]
    return pa.concat_tables(tables) if tables else meta.schema().empty_table()


def trial_streams(engine: Engine, trial_ids: Sequence[int]) -> list[LslStream]:
    """The stored streams of `trial_ids` (detached rows), by trial then name."""
    if not trial_ids:
        return []
    with Session(engine) as session:
        rows = session.scalars(
            select(LslStream)
            .where(LslStream.trial_id.in_(list(trial_ids)))
            .order_by(LslStream.trial_id, LslStream.name, LslStream.id)
        ).all()
        session.expunge_all()
    return list(rows)
