"""sample_chunks: samples stored per committed chunk as compressed Arrow columns

Before, a trial's samples were rows of `samples` (trial, seq, 14 columns): about 115
bytes a sample in SQLite, and reading them back cost 1.1 us of CPU a sample, which
held the Parquet export below a million samples a second; the writer bound
a Python value per sample. Now each committed chunk (at most a second of
trial time, as the writer commits) is one row of `sample_chunks` holding the chunk's
columns as one zstd-compressed Arrow record batch (`db.sample_codec`).

This revision moves every sample: a trial's rows in `seq` order are cut where the
writer would have cut them (a second of trial time from a chunk's first sample, and
at a gap in `seq`), encoded, and stored; then `samples` is dropped. The downgrade
decodes the chunks back into rows.

Revision ID: 0005_sample_chunks
Revises: 0004_trial_measures
"""

from collections.abc import Iterator, Sequence
from typing import Any

import pyarrow as pa
import sqlalchemy as sa
from alembic import op

from db.sample_codec import column_array, decode, encode

revision: str = "0005_sample_chunks"
down_revision: str | None = "0004_trial_measures"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

COLUMNS = (
    "t_s",
    "insertion_m",
    "rotation_rad",
    "tip_x_m",
    "tip_y_m",
    "tip_z_m",
    "branch",
    "proximal_force_n",
    "proximal_force_est_n",
    "distal_force_n",
    "dial_angle_rad",
    "dial_torque_n_m",
)
"""The value columns of `samples` at revision 0004, in table order (frozen here)."""
SCHEMA = pa.schema(
    [pa.field(c, pa.string() if c == "branch" else pa.float64(), c != "t_s") for c in COLUMNS]
)
CHUNK_S = 1.0
"""Longest span of trial time in one chunk, s (the writer's default)."""
MAX_ROWS = 65_536
FETCH_ROWS = 20_000

SAMPLES = sa.table(
    "samples",
    sa.column("trial_id", sa.Integer()),
    sa.column("seq", sa.BigInteger()),
    *(sa.column(c, sa.String() if c == "branch" else sa.Double()) for c in COLUMNS),
)


def _chunks_table(conn: sa.Connection) -> sa.Table:
    return sa.Table("sample_chunks", sa.MetaData(), autoload_with=conn)


def _cut(rows: Iterator[Sequence[Any]]) -> Iterator[tuple[int, int, list[Sequence[Any]]]]:
    """(trial id, first seq, rows) per chunk of the rows (ordered by trial and seq)."""
    held: list[Sequence[Any]] = []
    key: tuple[Any, Any, Any] = (None, None, None)  # trial, next seq, chunk start time
    for row in rows:
        trial_id, seq, t_s = row[0], row[1], row[2]
        same = trial_id == key[0] and seq == key[1] and t_s < key[2] + CHUNK_S
        if held and (not same or len(held) >= MAX_ROWS):
            yield held[0][0], held[0][1], held
            held = []
        if not held:
            key = (trial_id, seq, t_s)
        held.append(row)
        key = (trial_id, seq + 1, key[2])
    if held:
        yield held[0][0], held[0][1], held


def _rows(conn: sa.Connection) -> Iterator[Sequence[Any]]:
    """Every row of `samples` in trial and `seq` order, a page at a time (keyset pages:
    no server-side cursor open while the chunks are inserted)."""
    trial_ids = conn.execute(sa.select(SAMPLES.c.trial_id).distinct()).scalars().all()
    for trial_id in sorted(trial_ids):
        last = None
        while True:
            query = sa.select(SAMPLES).where(SAMPLES.c.trial_id == trial_id)
            if last is not None:
                query = query.where(SAMPLES.c.seq > last)
            page = conn.execute(query.order_by(SAMPLES.c.seq).limit(FETCH_ROWS)).all()
            yield from page
            if len(page) < FETCH_ROWS:
                break
            last = page[-1][1]


def upgrade() -> None:
    chunks = op.create_table(
        "sample_chunks",
        sa.Column("trial_id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("first_seq", sa.BigInteger(), autoincrement=False, nullable=False),
        sa.Column("n_samples", sa.Integer(), nullable=False),
        sa.Column("t_first_s", sa.Double(), nullable=False),
        sa.Column("t_last_s", sa.Double(), nullable=False),
        sa.Column("raw_bytes", sa.Integer(), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.CheckConstraint("n_samples > 0", name=op.f("ck_sample_chunks_chunk_not_empty")),
        sa.ForeignKeyConstraint(
            ["trial_id"],
            ["trials.id"],
            name=op.f("fk_sample_chunks_trial_id_trials"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("trial_id", "first_seq", name=op.f("pk_sample_chunks")),
    )
    conn = op.get_bind()
    pending: list[dict[str, Any]] = []
    for trial_id, first_seq, rows in _cut(_rows(conn)):
        values = list(zip(*rows, strict=True))[2:]
        n = len(rows)
        batch = pa.RecordBatch.from_arrays(
            [column_array(c, v, n, SCHEMA) for c, v in zip(COLUMNS, values, strict=True)],
            schema=SCHEMA,
        )
        data, raw_bytes = encode(batch)
        pending.append(
            {
                "trial_id": trial_id,
                "first_seq": first_seq,
                "n_samples": n,
                "t_first_s": float(rows[0][2]),
                "t_last_s": float(rows[-1][2]),
                "raw_bytes": raw_bytes,
                "data": data,
            }
        )
        if len(pending) >= 200:
            conn.execute(chunks.insert(), pending)
            pending = []
    if pending:
        conn.execute(chunks.insert(), pending)
    op.drop_table("samples")


def downgrade() -> None:
    samples = op.create_table(
        "samples",
        sa.Column("trial_id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("seq", sa.BigInteger(), autoincrement=False, nullable=False),
        *(
            sa.Column(
                c, sa.String(length=16) if c == "branch" else sa.Double(), nullable=c != "t_s"
            )
            for c in COLUMNS
        ),
        sa.ForeignKeyConstraint(
            ["trial_id"],
            ["trials.id"],
            name=op.f("fk_samples_trial_id_trials"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("trial_id", "seq", name=op.f("pk_samples")),
    )
    conn = op.get_bind()
    chunks = _chunks_table(conn)
    keys = conn.execute(
        sa.select(chunks.c.trial_id, chunks.c.first_seq).order_by(
            chunks.c.trial_id, chunks.c.first_seq
        )
    ).all()
    for trial_id, first_seq in keys:
        raw_bytes, data = conn.execute(
            sa.select(chunks.c.raw_bytes, chunks.c.data).where(
                chunks.c.trial_id == trial_id, chunks.c.first_seq == first_seq
            )
        ).one()
        columns = decode(data, raw_bytes, SCHEMA).to_pydict()
        n = len(columns["t_s"])
        rows = [
            {"trial_id": trial_id, "seq": first_seq + k, **{c: columns[c][k] for c in COLUMNS}}
            for k in range(n)
        ]
        conn.execute(samples.insert(), rows)
    op.drop_table("sample_chunks")
