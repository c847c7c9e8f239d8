"""Revision 0009: a database of the previous revision, with a trial stored, opens upgraded;
the trial is valid (no reason) and can be marked invalid."""

from __future__ import annotations

from sqlalchemy import inspect, text

from db.engine import make_engine
from db.migrate import open_database, upgrade_schema


def test_a_database_at_0008_opens_with_its_trials_valid(db_url: str) -> None:
    engine = make_engine(db_url)
    upgrade_schema(engine, "0008_probe_trials")
    with engine.begin() as conn:
        assert "invalid_reason" not in {c["name"] for c in inspect(conn).get_columns("trials")}
        conn.execute(
            text(
                "INSERT INTO studies (id, name, design_toml, design, seed, created_at) "
                "VALUES (1, 's', '', '{}', 1, CURRENT_TIMESTAMP)"
            )
        )
        conn.execute(
            text(
                'INSERT INTO participants (id, study_id, code, "group", condition_order, '
                "created_at) VALUES (1, 1, 'P001', 'novice', '[\"VO\", \"HV\"]', "
                "CURRENT_TIMESTAMP)"
            )
        )
        conn.execute(
            text(
                "INSERT INTO trials (id, participant_id, task, condition, block_index, "
                "trial_index, practice, attempt, status, created_at, completion_time_s) "
                "VALUES (1, 1, 'lcca', 'VO', 0, 0, false, 1, 'completed', CURRENT_TIMESTAMP, "
                "20.0)"
            )
        )
    engine.dispose()
    engine = open_database(db_url, create=False, upgrade=True)
    with engine.begin() as conn:
        rows = conn.execute(text("SELECT id, status, invalid_reason FROM trials")).all()
        assert rows == [(1, "completed", None)]
        conn.execute(text("UPDATE trials SET invalid_reason = 'slipped' WHERE id = 1"))
        assert conn.execute(text("SELECT invalid_reason FROM trials")).scalar() == "slipped"
    engine.dispose()
