"""`study bench db`: how fast one trial's samples are written through the real write path.

The benchmark creates a scratch study database (a temporary SQLite file, or a private
schema on a PostgreSQL server, dropped afterwards), adds one participant and one
trial, and streams `rows` samples at `rate_hz` through `db.samples.SampleWriter`, the
writer the session runner uses, committing one chunk per second of trial time.
"""

from __future__ import annotations

import tempfile
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
from sqlalchemy import URL, Engine, func, select, text

from db.engine import describe, make_engine, make_session_factory, resolve_url
from db.errors import DbInputError
from db.migrate import open_database
from db.models import Participant, SampleChunk, Study, Trial
from db.samples import SampleWriter
from study.protocol.tasks import get_task
from teleop_core.progress import Progress, no_progress

BENCH_TASK = "lcca"
"""The scratch trial's task: the writer stores its samples in the task's declared schema."""


def bench_schema() -> pa.Schema:
    """The scratch trial's sample schema (`BENCH_TASK`'s, as a session writes it)."""
    return get_task(BENCH_TASK).sample_schema()


@dataclass(frozen=True)
class WriteBenchResult:
    backend: str
    rows: int
    rate_hz: float
    chunk_s: float
    chunks: int
    seconds: float
    rows_per_s: float

    def to_dict(self) -> dict[str, float | int | str]:
        return asdict(self)


@contextmanager
def scratch_database(db: str | URL | None) -> Iterator[Engine]:
    """A fresh study database: a temporary SQLite file when `db` is None, else a private
    schema on the PostgreSQL server `db` names (SQLite URLs are refused: the benchmark
    never writes into a real study file)."""
    if db is None:
        with tempfile.TemporaryDirectory() as tmp:
            engine = open_database(str(Path(tmp) / "bench.db"))
            try:
                yield engine
            finally:
                engine.dispose()
        return
    url = resolve_url(db)
    if url.get_backend_name() != "postgresql":
        raise DbInputError(
            f"benchmark database {describe(url)!r} is not PostgreSQL; expected a "
            "postgresql+psycopg:// URL, or no --db for a temporary SQLite file"
        )
    schema = f"bench_{uuid.uuid4().hex[:12]}"
    admin = make_engine(url)
    with admin.begin() as conn:
        conn.execute(text(f'CREATE SCHEMA "{schema}"'))
    engine = open_database(url.update_query_dict({"options": f"-csearch_path={schema}"}))
    try:
        yield engine
    finally:
        engine.dispose()
        with admin.begin() as conn:
            conn.execute(text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


def scratch_trial(engine: Engine) -> int:
    with make_session_factory(engine).begin() as session:
        study = Study(name="bench", design_toml="", design={}, seed=0)
        participant = Participant(study=study, code="P001", group="bench", condition_order=[])
        trial = Trial(
            participant=participant,
            task=BENCH_TASK,
            condition="HV",
            block_index=0,
            trial_index=0,
            status="running",
            driver="simulated",
        )
        session.add(trial)
        session.flush()
        return trial.id


def synthetic_columns(rows: int, rate_hz: float, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(rows) / rate_hz
    return {
        "t_s": t,
        "insertion_m": 0.002 * t,
        "rotation_rad": np.sin(0.1 * t),
        "reference_force_n": np.abs(rng.normal(0.5, 0.2, rows)),
        "proximal_force_n": np.abs(rng.normal(0.5, 0.2, rows)),
        "distal_force_n": np.abs(rng.normal(0.1, 0.05, rows)),
        "dial_angle_rad": rng.normal(0.0, 0.3, rows),
        "dial_torque_n_m": rng.normal(0.0, 0.01, rows),
    }


def bench_sample_write(
    db: str | URL | None = None,
    *,
    rows: int = 1_000_000,
    rate_hz: float = 1000.0,
    chunk_s: float = 1.0,
    seed: int = 0,
    progress: Progress = no_progress,
) -> WriteBenchResult:
    """Write `rows` samples of one trial and time the writing (set-up excluded)."""
    with scratch_database(db) as engine:
        trial_id = scratch_trial(engine)
        columns = synthetic_columns(rows, rate_hz, seed)
        per_second = max(1, int(rate_hz))
        start = time.perf_counter()
        with SampleWriter(engine, trial_id, schema=bench_schema(), chunk_s=chunk_s) as writer:
            for lo in range(0, rows, per_second):
                writer.extend({k: v[lo : lo + per_second] for k, v in columns.items()})
                progress("writing samples", min(lo + per_second, rows), rows)
        seconds = time.perf_counter() - start
        with engine.connect() as conn:
            stored = conn.scalar(select(func.sum(SampleChunk.n_samples)))
        if stored != rows:
            raise RuntimeError(f"benchmark stored {stored} rows, expected {rows}")
        return WriteBenchResult(
            backend=engine.dialect.name,
            rows=rows,
            rate_hz=rate_hz,
            chunk_s=chunk_s,
            chunks=writer.chunks_committed,
            seconds=seconds,
            rows_per_s=rows / seconds,
        )
