"""Revision 0006: a database whose chunks all have the one old layout (revision 0005)
opens with each LCCA and NOTES chunk in its task's own schema (names, units,
descriptions), every value kept exactly, the NOTES demanded torque a NULL column (the
old layout had no place for it), and a task the revision does not know left in the old
layout; the downgrade gives the old layout back.

The old chunks are written here with plain pyarrow (the format `db.sample_codec`
describes) and read back the same way, the schema from `sample_schemas`; the expected
names are the tasks' own, written out by hand. At the head, revision 0010 names the
probe chunks too (`test_migration_old_layout_chunks.py`).
"""

from __future__ import annotations

import json
from datetime import UTC, datetime

import pyarrow as pa
from alembic import command
from sqlalchemy import Engine, text

from db.engine import make_engine
from db.migrate import alembic_config, head_revision, open_database
from study.protocol.tasks import get_task

OLD = "0005_sample_chunks"
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
OLD_SCHEMA = pa.schema(
    [pa.field(c, pa.string() if c == "branch" else pa.float64(), c != "t_s") for c in OLD_COLUMNS]
)
NOTES_NAMES = (
    "t_s",
    "insertion_m",
    "rotation_rad",
    "tip_x_m",
    "tip_y_m",
    "tip_z_m",
    "region",
    "force_demanded_n",
    "force_rendered_n",
    "tip_force_n",
    "dial_angle_rad",
    "torque_rendered_n_m",
    "torque_demanded_n_m",
)
LCCA_NAMES = (
    "t_s",
    "insertion_m",
    "rotation_rad",
    "tip_x_m",
    "tip_y_m",
    "tip_z_m",
    "branch",
    "reference_force_n",
    "proximal_force_n",
    "distal_force_n",
    "dial_angle_rad",
    "dial_torque_n_m",
)
TRIALS = {1: "lcca", 2: "notes", 3: "probe"}
"""Trial id -> task; `probe` stands for a lab's task the revision does not know."""


def _old_chunk(trial_id: int, first: int, n: int) -> pa.RecordBatch:
    """n samples whose every value says which trial, sample and column it is."""
    columns = []
    for k, name in enumerate(OLD_COLUMNS):
        if name == "branch":
            columns.append(pa.array([f"region{trial_id}"] * n))
        elif name == "distal_force_n" and trial_id == 2:
            columns.append(pa.array([None] * n, pa.float64()))  # NULLs kept too
        else:
            columns.append(pa.array([trial_id * 1000 + (first + i) + k / 100 for i in range(n)]))
    return pa.RecordBatch.from_arrays(columns, schema=OLD_SCHEMA)


def _old_database(url: str) -> dict[int, list[pa.RecordBatch]]:
    engine = make_engine(url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), OLD)
    now = datetime(2026, 11, 1, tzinfo=UTC)
    written: dict[int, list[pa.RecordBatch]] = {}
    with engine.begin() as conn:
        conn.execute(
            text(
                "INSERT INTO studies (id, name, design_toml, design, seed, created_at) "
                "VALUES (1, 's', '', :design, 1, :now)"
            ),
            {"design": json.dumps({"tasks": ["lcca", "notes"]}), "now": now},
        )
        conn.execute(
            text(
                'INSERT INTO participants (id, study_id, code, "group", condition_order, '
                "created_at) VALUES (1, 1, 'P001', 'novice', :order, :now)"
            ),
            {"order": json.dumps(["VO", "HV"]), "now": now},
        )
        for trial_id, task in TRIALS.items():
            conn.execute(
                text(
                    "INSERT INTO trials (id, participant_id, task, condition, block_index, "
                    "trial_index, practice, attempt, status, created_at) VALUES "
                    "(:id, 1, :task, 'VO', 0, :id, false, 1, 'completed', :now)"
                ),
                {"id": trial_id, "task": task, "now": now},
            )
            written[trial_id] = []
            for first, n in ((0, 5), (5, 3)):
                batch = _old_chunk(trial_id, first, n)
                message = batch.serialize()
                conn.execute(
                    text(
                        "INSERT INTO sample_chunks (trial_id, first_seq, n_samples, t_first_s, "
                        "t_last_s, raw_bytes, data) VALUES (:t, :f, :n, 0, 1, :raw, :data)"
                    ),
                    {
                        "t": trial_id,
                        "f": first,
                        "n": n,
                        "raw": message.size,
                        "data": pa.compress(message, codec="zstd", asbytes=True),
                    },
                )
                written[trial_id].append(batch)
    engine.dispose()
    return written


def _stored(engine: Engine, trial_id: int) -> list[pa.RecordBatch]:
    """The trial's chunks decoded with plain pyarrow in their stored schemas."""
    with engine.connect() as conn:
        rows = conn.execute(
            text(
                "SELECT c.raw_bytes, c.data, s.data FROM sample_chunks c JOIN sample_schemas s "
                "ON s.id = c.schema_id WHERE c.trial_id = :t ORDER BY c.first_seq"
            ),
            {"t": trial_id},
        ).all()
    out = []
    for raw_bytes, data, schema_data in rows:
        schema = pa.ipc.read_schema(pa.py_buffer(bytes(schema_data)))
        message = pa.decompress(bytes(data), decompressed_size=raw_bytes, codec="zstd")
        out.append(pa.ipc.read_record_batch(message, schema))
    return out


def _old_values(engine: Engine, trial_id: int) -> list[dict]:
    """The trial's chunks decoded in the old layout (after the downgrade)."""
    with engine.connect() as conn:
        rows = conn.execute(
            text(
                "SELECT raw_bytes, data FROM sample_chunks WHERE trial_id = :t ORDER BY first_seq"
            ),
            {"t": trial_id},
        ).all()
    return [
        pa.ipc.read_record_batch(
            pa.decompress(bytes(data), decompressed_size=raw, codec="zstd"), OLD_SCHEMA
        ).to_pydict()
        for raw, data in rows
    ]


def test_old_chunks_move_to_their_tasks_own_schemas_and_back(db_url: str) -> None:
    written = _old_database(db_url)
    engine = open_database(db_url, upgrade=True)  # upgrades to the head
    try:
        notes = _stored(engine, 2)
        assert [b.schema.names for b in notes] == [list(NOTES_NAMES)] * 2
        field = notes[0].schema.field("force_demanded_n")
        assert field.metadata == {
            b"unit": b"N",
            b"description": (b"tissue resistance on the scope, positive resisting insertion"),
        }
        for new, old in zip(notes, written[2], strict=True):
            assert new["region"] == old["branch"]
            assert new["force_demanded_n"] == old["proximal_force_n"]
            assert new["force_rendered_n"] == old["proximal_force_est_n"]
            assert new["tip_force_n"] == old["distal_force_n"]  # all NULL, kept NULL
            assert new["torque_rendered_n_m"] == old["dial_torque_n_m"]
            assert new["torque_demanded_n_m"].null_count == new.num_rows
            assert new["t_s"] == old["t_s"]
            assert new["tip_z_m"] == old["tip_z_m"]
        lcca = _stored(engine, 1)
        assert [b.schema.names for b in lcca] == [list(LCCA_NAMES)] * 2
        for new, old in zip(lcca, written[1], strict=True):
            assert new["reference_force_n"] == old["proximal_force_n"]
            assert new["proximal_force_n"] == old["proximal_force_est_n"]
            assert new["branch"] == old["branch"]
        # a task the revision does not know keeps the old layout, for revision 0010 to
        # name by its own frozen columns (the worked example's probe task)
        probe = _stored(engine, 3)
        assert [b.schema.names[7] for b in probe] == ["push_force_n"] * 2
        for new, old in zip(probe, written[3], strict=True):
            assert new["push_force_n"] == old["proximal_force_n"]
            assert new["depth_m"] == old["insertion_m"]
            assert new["aim_rad"] == old["dial_angle_rad"]
        # the application reads the migrated NOTES trial under its own names
        from db.sample_reader import SampleReader

        with SampleReader(engine) as reader:
            table = get_task("notes").sample_table(pa.Table.from_batches(list(reader.trial(2))))
        assert table.column_names == ["seq", *NOTES_NAMES]
        assert table["force_rendered_n"].to_pylist() == [
            v for b in written[2] for v in b["proximal_force_est_n"].to_pylist()
        ]
    finally:
        engine.dispose()

    engine = make_engine(db_url)
    try:
        with engine.begin() as conn:
            command.downgrade(alembic_config(conn), OLD)
        for trial_id in (1, 2):
            assert _old_values(engine, trial_id) == [b.to_pydict() for b in written[trial_id]]
        # the probe task has no place for the old layout's estimate, distal force and
        # torque: they come back NULL, the rest as written
        unmapped = {"proximal_force_est_n", "distal_force_n", "dial_torque_n_m"}
        for back, old in zip(_old_values(engine, 3), written[3], strict=True):
            for name, values in old.to_pydict().items():
                expected = [None] * len(values) if name in unmapped else values
                assert back[name] == expected, name
        with engine.begin() as conn:  # and up again, for the next test on this server
            command.upgrade(alembic_config(conn), head_revision())
    finally:
        engine.dispose()
