"""lsl_streams, lsl_chunks: the lab's other instruments recorded with a trial

Streams recorded through the Lab Streaming Layer beside the robot (EMG, an eye
tracker, a second camera) or imported from a LabRecorder XDF file: one `lsl_streams`
row per stream and trial (channels with units, the clocks that put its samples on the
trial's time, its gaps) and its samples in `lsl_chunks` (see `db.models.lsl`). New
tables only; nothing existing changes.

Revision ID: 0007_lsl_streams
Revises: 0006_task_sample_schemas
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0007_lsl_streams"
down_revision: str | None = "0006_task_sample_schemas"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "lsl_streams",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("trial_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=128), nullable=False),
        sa.Column("type", sa.String(length=64), nullable=False),
        sa.Column("source_id", sa.String(length=256), nullable=False),
        sa.Column("hostname", sa.String(length=256), nullable=False),
        sa.Column("channel_format", sa.String(length=16), nullable=False),
        sa.Column("nominal_srate_hz", sa.Double(), nullable=False),
        sa.Column("channels", sa.JSON(), nullable=False),
        sa.Column("lsl_t0_s", sa.Double(), nullable=False),
        sa.Column("time_correction_s", sa.Double(), nullable=False),
        sa.Column("clock_rate", sa.Double(), nullable=False),
        sa.Column("origin", sa.String(length=8), nullable=False),
        sa.Column("n_samples", sa.Integer(), nullable=False),
        sa.Column("gaps", sa.JSON(), nullable=False),
        sa.CheckConstraint("origin IN ('live', 'xdf')", name=op.f("ck_lsl_streams_origin_known")),
        sa.CheckConstraint("clock_rate > 0", name=op.f("ck_lsl_streams_clock_rate_positive")),
        sa.CheckConstraint("n_samples >= 0", name=op.f("ck_lsl_streams_n_samples_nonneg")),
        sa.ForeignKeyConstraint(
            ["trial_id"],
            ["trials.id"],
            name=op.f("fk_lsl_streams_trial_id_trials"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_lsl_streams")),
        sa.UniqueConstraint(
            "trial_id", "name", "source_id", name=op.f("uq_lsl_streams_trial_id_name_source_id")
        ),
    )
    with op.batch_alter_table("lsl_streams", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_lsl_streams_trial_id"), ["trial_id"], unique=False)

    op.create_table(
        "lsl_chunks",
        sa.Column("stream_id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("first_seq", sa.BigInteger(), autoincrement=False, nullable=False),
        sa.Column("n_samples", sa.Integer(), nullable=False),
        sa.Column("t_first_s", sa.Double(), nullable=False),
        sa.Column("t_last_s", sa.Double(), nullable=False),
        sa.Column("raw_bytes", sa.Integer(), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.CheckConstraint("n_samples > 0", name=op.f("ck_lsl_chunks_chunk_not_empty")),
        sa.ForeignKeyConstraint(
            ["stream_id"],
            ["lsl_streams.id"],
            name=op.f("fk_lsl_chunks_stream_id_lsl_streams"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("stream_id", "first_seq", name=op.f("pk_lsl_chunks")),
    )


def downgrade() -> None:
    op.drop_table("lsl_chunks")
    with op.batch_alter_table("lsl_streams", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_lsl_streams_trial_id"))

    op.drop_table("lsl_streams")
