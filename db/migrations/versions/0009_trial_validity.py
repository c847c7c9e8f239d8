"""trials: a measured trial marked invalid keeps its row, with the reason

A completed trial the experimenter judges invalid (the participant was distracted, the
device slipped) stays in the database and in every export; `invalid_reason` names why,
and the analysis leaves the trial out and lists it among its exclusions. Empty: valid.
Each change is an audit row (`study.protocol.corrections`).

Revision ID: 0009_trial_validity
Revises: 0008_probe_trials
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0009_trial_validity"
down_revision: str | None = "0008_probe_trials"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # a plain ALTER TABLE on both backends: a batch copy of `trials` on SQLite would drop
    # the old table, and with it (ON DELETE CASCADE) every trial's samples and measures
    op.add_column("trials", sa.Column("invalid_reason", sa.Text(), nullable=True))


def downgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        # SQLite drops a column in place since 3.35 (no table copy, see upgrade)
        op.execute("ALTER TABLE trials DROP COLUMN invalid_reason")
    else:
        op.drop_column("trials", "invalid_reason")
