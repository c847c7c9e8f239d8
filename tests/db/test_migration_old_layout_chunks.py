"""Revision 0010 on a database the previous code wrote (`data/revision_0009_old_layout_
chunks.db`, made by `data/make_revision_0009_old_layout_chunks.py` with haptic-study at
revision 0009): the chunks a sample writer given no schema left in the old layout (an
LCCA and a probe trial) move to their tasks' own names, every value of the tasks'
columns kept; the chunks
the session runner wrote in the LCCA schema are not touched; the downgrade gives the
probe chunks their old layout back.

The chunks are read with plain pyarrow and the schema rows of `sample_schemas`; the
expected values are the ones the script wrote, written out again by hand.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from alembic import command
from sqlalchemy import Engine, text

from db.engine import make_engine
from db.migrate import alembic_config, head_revision, open_database

OLD_DB = Path(__file__).parent / "data" / "revision_0009_old_layout_chunks.db"
K = np.arange(150)
"""The script's sample index: 150 samples, 0.01 s apart, in two chunks."""


def _chunks(engine: Engine, trial_id: int) -> list[tuple[bytes, pa.Schema, pa.RecordBatch]]:
    """The trial's stored chunks: (stored bytes, schema, batch), in `seq` order."""
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
        out.append((bytes(data), schema, pa.ipc.read_record_batch(message, schema)))
    return out


def _table(engine: Engine, trial_id: int) -> pa.Table:
    return pa.Table.from_batches([b for _, _, b in _chunks(engine, trial_id)])


@pytest.fixture
def old_db(tmp_path: Path) -> str:
    path = tmp_path / "old.db"
    shutil.copy(OLD_DB, path)
    return f"sqlite:///{path}"


def test_the_old_layout_chunks_of_a_database_of_revision_0009_take_their_tasks_names(
    old_db: str,
) -> None:
    before = make_engine(old_db)
    with before.connect() as conn:
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == (
            "0009_trial_validity"
        )
        schemas_before = conn.execute(text("SELECT count(*) FROM sample_schemas")).scalar()
    session_chunks = _chunks(before, 1)
    assert session_chunks
    assert session_chunks[0][1].names[7:9] == [
        "reference_force_n",
        "proximal_force_n",
    ]
    before.dispose()

    engine = open_database(old_db, upgrade=True)  # as `study db upgrade`
    with engine.connect() as conn:
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == (
            head_revision()
        )
        # one schema more: the probe's (the LCCA's and the NOTES' were stored by 0006)
        assert conn.execute(text("SELECT count(*) FROM sample_schemas")).scalar() == (
            schemas_before + 1
        )
    # the session's chunks: the same bytes in the same schema
    assert [(d, s) for d, s, _ in _chunks(engine, 1)] == [(d, s) for d, s, _ in session_chunks]

    lcca = _table(engine, 3)
    assert lcca.schema.names == [
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
    ]
    # the old layout's true force (proximal_force_n) is the reference, its estimate
    # (proximal_force_est_n) the task's proximal_force_n
    np.testing.assert_array_equal(lcca["reference_force_n"].to_numpy(), 0.5 + 0.001 * K)
    np.testing.assert_array_equal(lcca["proximal_force_n"].to_numpy(), 0.4 + 0.001 * K)
    np.testing.assert_array_equal(lcca["t_s"].to_numpy(), 0.01 * (K + 1))
    assert set(lcca["branch"].to_pylist()) == {"DAo"}

    probe = _table(engine, 4)
    assert probe.schema.names == [
        "t_s",
        "depth_m",
        "roll_rad",
        "tip_x_m",
        "tip_y_m",
        "tip_z_m",
        "where",
        "push_force_n",
        "aim_rad",
        "medium_speed_m_s",
    ]
    np.testing.assert_array_equal(probe["depth_m"].to_numpy(), 0.001 * K)
    np.testing.assert_array_equal(probe["push_force_n"].to_numpy(), 0.5 + 0.001 * K)
    np.testing.assert_array_equal(probe["aim_rad"].to_numpy(), np.full(150, 0.8))
    assert probe["medium_speed_m_s"].null_count == 150  # the old layout had no place for it
    assert set(probe["where"].to_pylist()) == {"medium"}
    assert probe.schema.field("push_force_n").metadata == {
        b"unit": b"N",
        b"description": b"the medium's push back",
    }

    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), "0009_trial_validity")
    back = _table(engine, 4)
    assert back.schema.names[7:9] == ["proximal_force_n", "proximal_force_est_n"]
    np.testing.assert_array_equal(back["proximal_force_n"].to_numpy(), 0.5 + 0.001 * K)
    assert back["proximal_force_est_n"].null_count == 150  # the script's estimate is gone
    engine.dispose()
