"""sample_schemas: each chunk stored in its task's own Arrow schema

Before, every trial's chunks had one schema, the LCCA-shaped layout of revision 0005
(`t_s ... branch, proximal_force_n, proximal_force_est_n, distal_force_n,
dial_angle_rad, dial_torque_n_m`): NOTES samples were stored under LCCA names (its
rendered force as `proximal_force_est_n`) and its demanded roll torque was not stored.
Now each chunk names its schema (`sample_chunks.schema_id` -> `sample_schemas`, an
Arrow IPC schema message): the trial's task's own columns, each with its unit and
description in the field's metadata.

This revision stores the old layout as a schema and gives it to every chunk; then it
re-encodes the chunks of the LCCA and NOTES trials under their tasks' own names and
schemas (frozen below as they were at this revision; the NOTES demanded torque, which
the old layout had no column for, is NULL in them). Chunks of a task this revision does
not know keep the old layout: readers map it to the task's names through the task's
`stored_as` (`study.protocol.tasks.SampleColumn`). The downgrade re-encodes every chunk
in the old layout (dropping the columns it has no place for) and drops the schemas.

Revision ID: 0006_task_sample_schemas
Revises: 0005_sample_chunks
"""

import hashlib
from collections.abc import Sequence

import pyarrow as pa
import sqlalchemy as sa
from alembic import op

from db.sample_codec import decode, encode

revision: str = "0006_task_sample_schemas"
down_revision: str | None = "0005_sample_chunks"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

OLD_COLUMNS = (
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
"""The chunks' one layout at revision 0005 (frozen here)."""
OLD_SCHEMA = pa.schema(
    [pa.field(c, pa.string() if c == "branch" else pa.float64(), c != "t_s") for c in OLD_COLUMNS]
)

_POSE = ("t_s", "insertion_m", "rotation_rad", "tip_x_m", "tip_y_m", "tip_z_m")
TASK_COLUMNS: dict[str, tuple[tuple[str, str | None, str, str], ...]] = {
    "lcca": (
        ("t_s", "t_s", "s", "time since the trial started"),
        ("insertion_m", "insertion_m", "m", "guidewire inserted"),
        ("rotation_rad", "rotation_rad", "rad", "guidewire roll"),
        ("tip_x_m", "tip_x_m", "m", "tip position, phantom frame"),
        ("tip_y_m", "tip_y_m", "m", "tip position, phantom frame"),
        ("tip_z_m", "tip_z_m", "m", "tip position, phantom frame"),
        ("branch", "branch", "", "vessel the tip is in (DAo, arch, ...)"),
        (
            "reference_force_n",
            "proximal_force_n",
            "N",
            "true proximal insertion force (simulation) or reference sensor",
        ),
        (
            "proximal_force_n",
            "proximal_force_est_n",
            "N",
            "proximal force estimated from the motor current (what is rendered)",
        ),
        ("distal_force_n", "distal_force_n", "N", "tip force on the vessel wall"),
        ("dial_angle_rad", "dial_angle_rad", "rad", "haptic dial angle"),
        ("dial_torque_n_m", "dial_torque_n_m", "N m", "torque on the hand"),
    ),
    "notes": (
        ("t_s", "t_s", "s", "time since the trial started"),
        ("insertion_m", "insertion_m", "m", "scope depth from the introitus"),
        ("rotation_rad", "rotation_rad", "rad", "scope roll"),
        ("tip_x_m", "tip_x_m", "m", "tip position"),
        ("tip_y_m", "tip_y_m", "m", "tip position"),
        ("tip_z_m", "tip_z_m", "m", "tip position"),
        ("region", "branch", "", "where the tip is (canal, fornix, ...)"),
        (
            "force_demanded_n",
            "proximal_force_n",
            "N",
            "tissue resistance on the scope, positive resisting insertion",
        ),
        (
            "force_rendered_n",
            "proximal_force_est_n",
            "N",
            "force the device renders (saturates at its continuous limit)",
        ),
        (
            "tip_force_n",
            "distal_force_n",
            "N",
            "the tissue's push on the tip (the fornix or the fold)",
        ),
        ("dial_angle_rad", "dial_angle_rad", "rad", "the hand's aim (rate input)"),
        ("torque_rendered_n_m", "dial_torque_n_m", "N m", "torque rendered"),
        (
            "torque_demanded_n_m",
            None,
            "N m",
            "tissue resistance to roll, positive resisting clockwise roll",
        ),
    ),
}
"""Each task's sample columns at this revision: (its name, the old layout's column that
held it or None, unit, description), in the task's order."""
REGION_COLUMNS = ("branch", "region")
PAGE = 200


def _schema(task: str) -> pa.Schema:
    return pa.schema(
        [
            pa.field(
                name,
                pa.string() if name in REGION_COLUMNS else pa.float64(),
                name != "t_s",
                metadata={"unit": unit, "description": description},
            )
            for name, _, unit, description in TASK_COLUMNS[task]
        ]
    )


def _schemas_table() -> sa.TableClause:
    return sa.table(
        "sample_schemas",
        sa.column("id", sa.Integer()),
        sa.column("fingerprint", sa.String()),
        sa.column("data", sa.LargeBinary()),
    )


def _chunks_table() -> sa.TableClause:
    return sa.table(
        "sample_chunks",
        sa.column("trial_id", sa.Integer()),
        sa.column("first_seq", sa.BigInteger()),
        sa.column("raw_bytes", sa.Integer()),
        sa.column("schema_id", sa.Integer()),
        sa.column("data", sa.LargeBinary()),
    )


def _store(conn: sa.Connection, schema: pa.Schema) -> int:
    data = schema.serialize().to_pybytes()
    key = hashlib.sha256(data).hexdigest()
    table = _schemas_table()
    conn.execute(table.insert().values(fingerprint=key, data=data))
    return int(conn.execute(sa.select(table.c.id).where(table.c.fingerprint == key)).scalar_one())


def _recode(
    conn: sa.Connection, trial_ids: list[int], recode, schema_id: int, from_schemas
) -> None:
    """Re-encode every chunk of `trial_ids` with `recode(batch)`, keyset pages of chunks."""
    chunks = _chunks_table()
    for trial_id in trial_ids:
        last = -1
        while True:
            page = conn.execute(
                sa.select(chunks.c.first_seq, chunks.c.raw_bytes, chunks.c.schema_id, chunks.c.data)
                .where(chunks.c.trial_id == trial_id, chunks.c.first_seq > last)
                .order_by(chunks.c.first_seq)
                .limit(PAGE)
            ).all()
            for first_seq, raw_bytes, old_id, data in page:
                batch = recode(decode(data, raw_bytes, from_schemas[old_id]))
                new_data, new_raw = encode(batch)
                conn.execute(
                    chunks.update()
                    .where(chunks.c.trial_id == trial_id, chunks.c.first_seq == first_seq)
                    .values(data=new_data, raw_bytes=new_raw, schema_id=schema_id)
                )
            if len(page) < PAGE:
                break
            last = page[-1][0]


def _trials(conn: sa.Connection, task: str | None) -> list[int]:
    """The ids of `task`'s trials that have chunks (None: every trial that has)."""
    trials = sa.table("trials", sa.column("id", sa.Integer()), sa.column("task", sa.String()))
    chunks = _chunks_table()
    query = sa.select(chunks.c.trial_id).distinct()
    if task is not None:
        query = query.join(trials, trials.c.id == chunks.c.trial_id).where(trials.c.task == task)
    return sorted(conn.execute(query).scalars().all())


def upgrade() -> None:
    op.create_table(
        "sample_schemas",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("fingerprint", sa.String(length=64), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_sample_schemas")),
        sa.UniqueConstraint("fingerprint", name=op.f("uq_sample_schemas_fingerprint")),
    )
    with op.batch_alter_table("sample_chunks") as batch_op:
        batch_op.add_column(sa.Column("schema_id", sa.Integer(), nullable=True))
    conn = op.get_bind()
    old_id = _store(conn, OLD_SCHEMA)
    conn.execute(_chunks_table().update().values(schema_id=old_id))
    for task, columns in TASK_COLUMNS.items():
        schema = _schema(task)
        schema_id = _store(conn, schema)

        def recode(batch: pa.RecordBatch, columns=columns, schema=schema) -> pa.RecordBatch:
            n = batch.num_rows
            arrays = [
                batch.column(old) if old is not None else pa.nulls(n, field.type)
                for (_, old, _, _), field in zip(columns, schema, strict=True)
            ]
            return pa.RecordBatch.from_arrays(arrays, schema=schema)

        _recode(conn, _trials(conn, task), recode, schema_id, {old_id: OLD_SCHEMA})
    with op.batch_alter_table("sample_chunks") as batch_op:
        batch_op.alter_column("schema_id", existing_type=sa.Integer(), nullable=False)
        batch_op.create_foreign_key(
            batch_op.f("fk_sample_chunks_schema_id_sample_schemas"),
            "sample_schemas",
            ["schema_id"],
            ["id"],
        )


def downgrade() -> None:
    conn = op.get_bind()
    table = _schemas_table()
    schemas = {
        int(i): pa.ipc.read_schema(pa.py_buffer(data))
        for i, data in conn.execute(sa.select(table.c.id, table.c.data))
    }

    def recode(batch: pa.RecordBatch) -> pa.RecordBatch:
        """The old layout's columns of `batch`, by the tasks' frozen mappings."""
        names = dict.fromkeys(batch.schema.names)
        for columns in TASK_COLUMNS.values():
            if [c[0] for c in columns] == list(names):
                source = {old: name for name, old, _, _ in columns if old is not None}
                break
        else:  # the old layout, or a schema it cannot name: by name where it matches
            source = {c: c for c in OLD_COLUMNS if c in names}
        arrays = [
            batch.column(source[c]) if c in source else pa.nulls(batch.num_rows, f.type)
            for c, f in zip(OLD_COLUMNS, OLD_SCHEMA, strict=True)
        ]
        return pa.RecordBatch.from_arrays(arrays, schema=OLD_SCHEMA)

    with op.batch_alter_table("sample_chunks") as batch_op:
        batch_op.drop_constraint(
            batch_op.f("fk_sample_chunks_schema_id_sample_schemas"), type_="foreignkey"
        )
    _recode(conn, _trials(conn, None), recode, 0, schemas)
    with op.batch_alter_table("sample_chunks") as batch_op:
        batch_op.drop_column("schema_id")
    op.drop_table("sample_schemas")
