"""trial_measures: each task's summary measures under their own names

Before, every task wrote its measures into the LCCA's columns: a NOTES trial's
`peak_proximal_force_n` held the force the tissue demanded and `peak_distal_force_n`
the fornix's force on the tip. Now a trial's measures are rows of `trial_measures`
(trial, name, value) named by their task (`study.protocol.tasks`); this revision moves
the values there (LCCA: peak_proximal_force_n, peak_distal_force_n, wall_contacts;
NOTES: peak_force_demanded_n, peak_tip_force_n, and the further peaks its summary kept)
and drops the three columns.

Revision ID: 0004_trial_measures
Revises: 0003_withdrawal
"""

import json
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004_trial_measures"
down_revision: str | None = "0003_withdrawal"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

COLUMN_MEASURES = {
    "lcca": {
        "peak_proximal_force_n": "peak_proximal_force_n",
        "peak_distal_force_n": "peak_distal_force_n",
        "wall_contacts": "wall_contacts",
    },
    "notes": {
        "peak_proximal_force_n": "peak_force_demanded_n",
        "peak_distal_force_n": "peak_tip_force_n",
    },
}
"""Old column -> measure name, per task."""
NOTES_SUMMARY_MEASURES = (
    "peak_force_rendered_n",
    "peak_torque_demanded_n_m",
    "peak_torque_rendered_n_m",
    "push_over_capacity_fraction",
)
CHECKS = {
    "peak_proximal_force_n": "peak_proximal_nonneg",
    "peak_distal_force_n": "peak_distal_nonneg",
    "wall_contacts": "wall_contacts_nonneg",
}


def upgrade() -> None:
    # read first, alter `trials`, then create `trial_measures`: on SQLite the batch
    # alteration recreates `trials`, which would cascade to rows already referencing it
    conn = op.get_bind()
    trials = sa.table(
        "trials",
        sa.column("id", sa.Integer()),
        sa.column("task", sa.String()),
        sa.column("summary", sa.JSON()),
        *(sa.column(c, sa.Double()) for c in CHECKS),
    )
    rows = []
    for task, columns in COLUMN_MEASURES.items():
        for column, name in columns.items():
            for trial_id, value in conn.execute(
                sa.select(trials.c.id, trials.c[column]).where(
                    trials.c.task == task, trials.c[column].is_not(None)
                )
            ):
                rows.append({"trial_id": trial_id, "name": name, "value": float(value)})
    for trial_id, summary in conn.execute(
        sa.select(trials.c.id, trials.c.summary).where(trials.c.task == "notes")
    ):
        summary = json.loads(summary) if isinstance(summary, str) else (summary or {})
        for name in NOTES_SUMMARY_MEASURES:
            if isinstance(summary.get(name), int | float):
                rows.append({"trial_id": trial_id, "name": name, "value": float(summary[name])})
    with op.batch_alter_table("trials") as batch:
        for column, check in CHECKS.items():
            batch.drop_constraint(op.f(f"ck_trials_{check}"), type_="check")
            batch.drop_column(column)
    measures = op.create_table(
        "trial_measures",
        sa.Column("trial_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("value", sa.Double(), nullable=False),
        sa.ForeignKeyConstraint(
            ["trial_id"],
            ["trials.id"],
            name=op.f("fk_trial_measures_trial_id_trials"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("trial_id", "name", name=op.f("pk_trial_measures")),
    )
    if rows:
        op.bulk_insert(measures, rows)


def downgrade() -> None:
    conn = op.get_bind()
    kept = conn.execute(sa.text("SELECT trial_id, name, value FROM trial_measures")).all()
    op.drop_table("trial_measures")
    with op.batch_alter_table("trials") as batch:
        batch.add_column(sa.Column("peak_proximal_force_n", sa.Double(), nullable=True))
        batch.add_column(sa.Column("peak_distal_force_n", sa.Double(), nullable=True))
        batch.add_column(sa.Column("wall_contacts", sa.Integer(), nullable=True))
        for column, check in CHECKS.items():
            batch.create_check_constraint(op.f(f"ck_trials_{check}"), f"{column} >= 0")
    tasks: dict[int, str] = dict(conn.execute(sa.text("SELECT id, task FROM trials")).all())
    for trial_id, name, value in kept:
        for column, measure in COLUMN_MEASURES.get(tasks.get(trial_id, ""), {}).items():
            if measure == name:
                value = int(value) if column == "wall_contacts" else value
                conn.execute(
                    sa.text(f"UPDATE trials SET {column} = :v WHERE id = :id"),
                    {"v": value, "id": trial_id},
                )
