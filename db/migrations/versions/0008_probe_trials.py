"""probe_trials: the probes' trials, one row per participant x probe x trial

Probes (short psychophysical measurements before a task's first block: a force
threshold, reaction times, aiming, a comfort torque) tell the participant model what
the task's trials cannot. This revision adds their table; nothing existing changes.

Revision ID: 0008_probe_trials
Revises: 0007_lsl_streams
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008_probe_trials"
down_revision: str | None = "0007_lsl_streams"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "probe_trials",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("probe", sa.String(length=32), nullable=False),
        sa.Column("trial_index", sa.Integer(), nullable=False),
        sa.Column("stimulus", sa.Double(), nullable=True),
        sa.Column("response", sa.Double(), nullable=True),
        sa.Column("correct", sa.Boolean(), nullable=True),
        sa.Column("context", sa.JSON(), nullable=False),
        sa.Column("driver", sa.String(length=16), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.CheckConstraint("trial_index >= 0", name=op.f("ck_probe_trials_trial_index_nonneg")),
        sa.ForeignKeyConstraint(
            ["participant_id"],
            ["participants.id"],
            name=op.f("fk_probe_trials_participant_id_participants"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_probe_trials")),
        sa.UniqueConstraint(
            "participant_id",
            "probe",
            "trial_index",
            name=op.f("uq_probe_trials_participant_id_probe_trial_index"),
        ),
    )
    op.create_index(
        op.f("ix_probe_trials_participant_id"), "probe_trials", ["participant_id"], unique=False
    )


def downgrade() -> None:
    op.drop_index(op.f("ix_probe_trials_participant_id"), table_name="probe_trials")
    op.drop_table("probe_trials")
