"""A chunk that kept the old layout (its trial's task unknown to the upgrades that renamed
the chunks of LCCA, NOTES and the worked example's probe) is read at the head by its
stored schema alone, with its names and values as written: the application holds no
copy of the old layout to read it by.

The database is built at revision 0010 and the chunks written there with plain pyarrow
(the format `db.sample_codec` describes) under the old layout's schema row as revision
0006 stored it; the expected names and values are the ones written here.
"""

from __future__ import annotations

import hashlib
import json
from datetime import UTC, datetime

import pyarrow as pa
import pytest
from alembic import command
from sqlalchemy import Engine, text
from sqlalchemy.exc import IntegrityError

from db.engine import make_engine
from db.migrate import alembic_config, open_database
from db.sample_reader import SampleReader, SampleSpan, plan_spans, read_spans

REVISION = "0010_old_layout_chunks"
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
TRIAL_ID = 7
CHUNKS = ((0, 4), (4, 3))
"""(first seq, samples) of the trial's two chunks."""


def _value(name: str, seq: int) -> object:
    """Sample `seq`'s value of column `name`: says which sample and column it is;
    `distal_force_n` NULL on odd samples (NULLs are kept too)."""
    k = OLD_COLUMNS.index(name)
    if name == "t_s":
        return seq / 100
    if name == "branch":
        return f"stage{seq % 2}"
    if name == "distal_force_n" and seq % 2:
        return None
    return seq + k / 100


def _at_revision_0010(url: str) -> None:
    """A database at revision 0010 holding one trial of a task no revision knows
    (`tremor`), its chunks in the old layout."""
    engine = make_engine(url)
    try:
        with engine.begin() as conn:
            command.upgrade(alembic_config(conn), REVISION)
        _write(engine)
    finally:
        engine.dispose()


def _write(engine: Engine) -> None:
    now = datetime(2026, 11, 1, tzinfo=UTC)
    schema_data = OLD_SCHEMA.serialize().to_pybytes()
    with engine.begin() as conn:
        conn.execute(
            text(
                "INSERT INTO studies (id, name, design_toml, design, seed, created_at) "
                "VALUES (1, 's', '', :design, 1, :now)"
            ),
            {"design": json.dumps({"tasks": ["tremor"]}), "now": now},
        )
        conn.execute(
            text(
                'INSERT INTO participants (id, study_id, code, "group", condition_order, '
                "created_at) VALUES (1, 1, 'P001', 'novice', :order, :now)"
            ),
            {"order": json.dumps(["VO", "HV"]), "now": now},
        )
        conn.execute(
            text(
                "INSERT INTO trials (id, participant_id, task, condition, block_index, "
                "trial_index, practice, attempt, status, created_at) VALUES "
                "(:id, 1, 'tremor', 'VO', 0, 0, false, 1, 'completed', :now)"
            ),
            {"id": TRIAL_ID, "now": now},
        )
        # the old layout's row, stored by revision 0006
        schema_id = conn.execute(
            text("SELECT id FROM sample_schemas WHERE fingerprint = :key AND data = :data"),
            {"key": hashlib.sha256(schema_data).hexdigest(), "data": schema_data},
        ).scalar_one()
        for first, n in CHUNKS:
            arrays = [
                pa.array([_value(c, first + i) for i in range(n)], f.type)
                for c, f in zip(OLD_COLUMNS, OLD_SCHEMA, strict=True)
            ]
            message = pa.RecordBatch.from_arrays(arrays, schema=OLD_SCHEMA).serialize()
            conn.execute(
                text(
                    "INSERT INTO sample_chunks (trial_id, first_seq, n_samples, t_first_s, "
                    "t_last_s, raw_bytes, schema_id, data) "
                    "VALUES (:t, :f, :n, :t0, :t1, :raw, :schema, :data)"
                ),
                {
                    "t": TRIAL_ID,
                    "f": first,
                    "n": n,
                    "t0": first / 100,
                    "t1": (first + n - 1) / 100,
                    "raw": message.size,
                    "schema": schema_id,
                    "data": pa.compress(message, codec="zstd", asbytes=True),
                },
            )


def _expected() -> dict[str, list[object]]:
    seqs = range(sum(n for _, n in CHUNKS))
    return {"seq": list(seqs), **{c: [_value(c, s) for s in seqs] for c in OLD_COLUMNS}}


def test_an_unknown_tasks_old_layout_chunks_read_back_by_their_stored_schema(db_url: str) -> None:
    _at_revision_0010(db_url)
    engine = open_database(db_url, upgrade=True)  # up to the head, as `study db upgrade`
    try:
        with SampleReader(engine) as reader:
            trial = pa.Table.from_batches(list(reader.trial(TRIAL_ID)))
            outside = reader.span(SampleSpan((TRIAL_ID,)), from_s=1.0)
        assert trial.column_names == ["seq", *OLD_COLUMNS]
        assert trial.to_pydict() == _expected()
        # a span that reads none of them still has their columns
        assert outside.num_rows == 0
        assert outside.column_names == ["trial_id", "seq", *OLD_COLUMNS]
        spans = [s for per_trial in plan_spans(engine, [TRIAL_ID]) for s in per_trial]
        (table,) = read_spans(engine, spans, lambda span, table: table)
        assert table.to_pydict() == {"trial_id": [TRIAL_ID] * 7, **_expected()}
    finally:
        engine.dispose()


def test_no_chunk_can_be_stored_without_a_schema(db_url: str) -> None:
    """Why no chunk needs a layout to be read by when it names none: from revision 0006
    on, `sample_chunks.schema_id` may not be NULL."""
    _at_revision_0010(db_url)
    engine = open_database(db_url, upgrade=True)
    try:
        with pytest.raises(IntegrityError), engine.begin() as conn:
            conn.execute(
                text(
                    "INSERT INTO sample_chunks (trial_id, first_seq, n_samples, t_first_s, "
                    "t_last_s, raw_bytes, schema_id, data) "
                    "VALUES (:t, 100, 1, 0, 0, 1, NULL, :data)"
                ),
                {"t": TRIAL_ID, "data": b"x"},
            )
    finally:
        engine.dispose()
