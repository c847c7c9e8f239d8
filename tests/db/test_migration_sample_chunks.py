"""Revision 0005: a database whose samples are rows (revision 0004) opens with every
sample in chunks, cut where the writer cuts (a second of trial time, a gap in `seq`),
every value kept exactly; the downgrade gives the same rows back.

The expected chunks are worked out by hand from the rows written here; the expected
values are the ones written.
"""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime

from alembic import command
from sqlalchemy import Engine, inspect, text

from db.engine import make_engine
from db.migrate import alembic_config, head_revision, inspect_database, open_database
from db.sample_reader import SampleReader

OLD = "0004_trial_measures"
COLUMNS = ("t_s", "insertion_m", "branch", "proximal_force_n", "distal_force_n")
HEAD_COLUMNS = ("t_s", "insertion_m", "branch", "reference_force_n", "distal_force_n")
"""The same columns at the head, under the LCCA task's own names (revision 0006)."""


def _rows() -> dict[int, list[tuple[int, float, float | None, str | None, float, float | None]]]:
    """trial -> (seq, t_s, insertion_m, branch, proximal_force_n, distal_force_n) rows.

    Trial 1: 2,500 samples at 1 kHz. Trial 2: 100 Hz, seq 0-99 then (after a gap, a
    restart) 150-299, with NULLs and a branch.
    """
    one = [(k, k / 1000, k * 1e-4, None, math.sin(k / 7), None) for k in range(2500)]
    two = [
        (k, k / 100, None, "arch" if k < 200 else "LCCA", 0.1 * k, None if k % 3 else -k / 9)
        for k in [*range(100), *range(150, 300)]
    ]
    return {1: one, 2: two}


def _old_database(url: str) -> None:
    engine = make_engine(url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), OLD)
    now = datetime(2026, 11, 1, tzinfo=UTC)
    with engine.begin() as conn:
        conn.execute(
            text(
                "INSERT INTO studies (id, name, design_toml, design, seed, created_at) "
                "VALUES (1, 's', '', :design, 1, :now)"
            ),
            {"design": json.dumps({"tasks": ["lcca"]}), "now": now},
        )
        conn.execute(
            text(
                'INSERT INTO participants (id, study_id, code, "group", condition_order, '
                "created_at) VALUES (1, 1, 'P001', 'novice', :order, :now)"
            ),
            {"order": json.dumps(["VO", "HV"]), "now": now},
        )
        for trial_id, rows in _rows().items():
            conn.execute(
                text(
                    "INSERT INTO trials (id, participant_id, task, condition, block_index, "
                    "trial_index, practice, attempt, status, created_at) VALUES "
                    "(:id, 1, 'lcca', 'VO', 0, :id, false, 1, 'completed', :now)"
                ),
                {"id": trial_id, "now": now},
            )
            conn.execute(
                text(
                    "INSERT INTO samples (trial_id, seq, t_s, insertion_m, branch, "
                    "proximal_force_n, distal_force_n) VALUES (:trial, :seq, :t, :x, :b, :p, :d)"
                ),
                [
                    {
                        "trial": trial_id,
                        "seq": r[0],
                        "t": r[1],
                        "x": r[2],
                        "b": r[3],
                        "p": r[4],
                        "d": r[5],
                    }
                    for r in rows
                ],
            )
    engine.dispose()


def _read_back(engine: Engine, trial_id: int) -> list[tuple]:
    with SampleReader(engine, batch_rows=700) as reader:
        return [
            (row["seq"], *(row[c] for c in HEAD_COLUMNS))
            for batch in reader.trial(trial_id)
            for row in batch.to_pylist()
        ]


def test_old_sample_rows_move_into_chunks_and_back(db_url: str) -> None:
    _old_database(db_url)
    assert inspect_database(db_url).samples == 2750  # `study db info`: the rows
    engine = open_database(db_url, upgrade=True)  # upgrades to the head
    assert inspect_database(db_url).samples == 2750  # and now the chunks' samples
    try:
        with engine.connect() as conn:
            chunks = conn.execute(
                text(
                    "SELECT trial_id, first_seq, n_samples, t_first_s, t_last_s FROM sample_chunks "
                    "ORDER BY trial_id, first_seq"
                )
            ).all()
            tables = set(inspect(conn).get_table_names())
        assert "samples" not in tables
        # 1 kHz: [0, 1) s, [1, 2) s, [2, 2.5) s. 100 Hz: seq 0-99, then from the gap
        # at t = 1.5 s: [1.5, 2.5) s and [2.5, 3) s.
        assert [tuple(c) for c in chunks] == [
            (1, 0, 1000, 0.0, 0.999),
            (1, 1000, 1000, 1.0, 1.999),
            (1, 2000, 500, 2.0, 2.499),
            (2, 0, 100, 0.0, 0.99),
            (2, 150, 100, 1.5, 2.49),
            (2, 250, 50, 2.5, 2.99),
        ]
        for trial_id, rows in _rows().items():
            assert _read_back(engine, trial_id) == rows  # exact doubles, NULLs kept
    finally:
        engine.dispose()

    engine = make_engine(db_url)
    try:
        with engine.begin() as conn:
            command.downgrade(alembic_config(conn), OLD)
        with engine.connect() as conn:
            back = {
                trial_id: [
                    tuple(r)
                    for r in conn.execute(
                        text(
                            "SELECT seq, t_s, insertion_m, branch, proximal_force_n, "
                            "distal_force_n FROM samples WHERE trial_id = :t ORDER BY seq"
                        ),
                        {"t": trial_id},
                    )
                ]
                for trial_id in (1, 2)
            }
        assert back == _rows()
        with engine.begin() as conn:  # and up again, for the next test on this server
            command.upgrade(alembic_config(conn), head_revision())
    finally:
        engine.dispose()
