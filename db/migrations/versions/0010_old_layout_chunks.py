"""sample_chunks: the chunks still in the old layout moved to their tasks' own schemas

Revision 0006 gave the LCCA and NOTES chunks their tasks' own schemas and left every
other chunk in the one layout of revision 0005 (`t_s ... branch, proximal_force_n,
proximal_force_est_n, distal_force_n, dial_angle_rad, dial_torque_n_m`), which readers
then mapped to each task's names through the task's `stored_as`. Chunks in that layout
also came later from a sample writer given no schema. This revision re-encodes every
chunk still in the old layout under its trial's task's own names and schema, for the
tasks it knows (frozen below as they were at this revision: LCCA, NOTES and the worked
example's `probe`), so that readers need no mapping. A chunk of a task it does not know
keeps the old layout and is read by its column names. The downgrade puts the `probe`
chunks back in the old layout (LCCA and NOTES chunks were in their own schemas at
revision 0009 as well).

Revision ID: 0010_old_layout_chunks
Revises: 0009_trial_validity
"""

import hashlib
from collections.abc import Sequence

import pyarrow as pa
import sqlalchemy as sa
from alembic import op

from db.sample_codec import decode, encode

revision: str = "0010_old_layout_chunks"
down_revision: str | None = "0009_trial_validity"
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
"""The old layout (frozen here)."""
OLD_SCHEMA = pa.schema(
    [pa.field(c, pa.string() if c == "branch" else pa.float64(), c != "t_s") for c in OLD_COLUMNS]
)
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
    "probe": (
        ("t_s", "t_s", "s", "time since the trial started"),
        ("depth_m", "insertion_m", "m", "probe depth"),
        ("roll_rad", "rotation_rad", "rad", "probe roll (none)"),
        ("tip_x_m", "tip_x_m", "m", "tip position"),
        ("tip_y_m", "tip_y_m", "m", "tip position"),
        ("tip_z_m", "tip_z_m", "m", "tip position"),
        ("where", "branch", "", "medium or at depth"),
        ("push_force_n", "proximal_force_n", "N", "the medium's push back"),
        ("aim_rad", "dial_angle_rad", "rad", "the hand's aim"),
        ("medium_speed_m_s", None, "m/s", "the probe's speed through the medium"),
    ),
}
"""Each task's sample columns at this revision: (its name, the old layout's column that
held it or None, unit, description), in the task's order."""
REGION_COLUMNS = {"lcca": "branch", "notes": "region", "probe": "where"}
PAGE = 200


def _schema(task: str) -> pa.Schema:
    return pa.schema(
        [
            pa.field(
                name,
                pa.string() if name == REGION_COLUMNS[task] else pa.float64(),
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


def _schema_id(conn: sa.Connection, schema: pa.Schema) -> int:
    """The id of `schema`'s row in `sample_schemas`, stored if it is not yet."""
    data = schema.serialize().to_pybytes()
    key = hashlib.sha256(data).hexdigest()
    table = _schemas_table()
    found = conn.execute(sa.select(table.c.id).where(table.c.fingerprint == key)).scalar()
    if found is None:
        conn.execute(table.insert().values(fingerprint=key, data=data))
        found = conn.execute(sa.select(table.c.id).where(table.c.fingerprint == key)).scalar_one()
    return int(found)


def _schemas(conn: sa.Connection) -> dict[int, pa.Schema]:
    table = _schemas_table()
    return {
        int(i): pa.ipc.read_schema(pa.py_buffer(data))
        for i, data in conn.execute(sa.select(table.c.id, table.c.data))
    }


def _recode(conn: sa.Connection, task: str, from_ids: set[int], recode, schema: pa.Schema) -> None:
    """Re-encode with `recode(batch)` into `schema` (stored only if a chunk needs it)
    every chunk of `task`'s trials whose schema is one of `from_ids`, in keyset pages."""
    chunks = _chunks_table()
    trials = sa.table("trials", sa.column("id", sa.Integer()), sa.column("task", sa.String()))
    schemas = _schemas(conn)
    ids = conn.execute(
        sa.select(chunks.c.trial_id)
        .distinct()
        .join(trials, trials.c.id == chunks.c.trial_id)
        .where(trials.c.task == task, chunks.c.schema_id.in_(sorted(from_ids)))
        .order_by(chunks.c.trial_id)
    ).scalars()
    trial_ids = list(ids)
    schema_id = _schema_id(conn, schema) if trial_ids else 0
    for trial_id in trial_ids:
        last = -1
        while True:
            page = conn.execute(
                sa.select(chunks.c.first_seq, chunks.c.raw_bytes, chunks.c.schema_id, chunks.c.data)
                .where(
                    chunks.c.trial_id == trial_id,
                    chunks.c.first_seq > last,
                    chunks.c.schema_id.in_(sorted(from_ids)),
                )
                .order_by(chunks.c.first_seq)
                .limit(PAGE)
            ).all()
            for first_seq, raw_bytes, old_id, data in page:
                new_data, new_raw = encode(recode(decode(data, raw_bytes, schemas[old_id])))
                conn.execute(
                    chunks.update()
                    .where(chunks.c.trial_id == trial_id, chunks.c.first_seq == first_seq)
                    .values(data=new_data, raw_bytes=new_raw, schema_id=schema_id)
                )
            if len(page) < PAGE:
                break
            last = page[-1][0]


def upgrade() -> None:
    conn = op.get_bind()
    old = {i for i, s in _schemas(conn).items() if s.names == list(OLD_COLUMNS)}
    if not old:
        return
    for task, columns in TASK_COLUMNS.items():
        schema = _schema(task)

        def recode(batch: pa.RecordBatch, columns=columns, schema=schema) -> pa.RecordBatch:
            arrays = [
                batch.column(source).cast(field.type)
                if source is not None
                else pa.nulls(batch.num_rows, field.type)
                for (_, source, _, _), field in zip(columns, schema, strict=True)
            ]
            return pa.RecordBatch.from_arrays(arrays, schema=schema)

        _recode(conn, task, old, recode, schema)


def downgrade() -> None:
    conn = op.get_bind()
    columns = TASK_COLUMNS["probe"]
    own = {i for i, s in _schemas(conn).items() if s.names == [c[0] for c in columns]}
    if not own:
        return
    source = {old: name for name, old, _, _ in columns if old is not None}

    def recode(batch: pa.RecordBatch) -> pa.RecordBatch:
        arrays = [
            batch.column(source[c]) if c in source else pa.nulls(batch.num_rows, f.type)
            for c, f in zip(OLD_COLUMNS, OLD_SCHEMA, strict=True)
        ]
        return pa.RecordBatch.from_arrays(arrays, schema=OLD_SCHEMA)

    _recode(conn, "probe", own, recode, OLD_SCHEMA)
