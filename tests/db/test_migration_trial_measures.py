"""Revision 0004: a database written before tasks had their own measures (NOTES values in
the LCCA's columns) opens with each value under its task's name, and downgrades back."""

from __future__ import annotations

import json
from datetime import UTC, datetime

from alembic import command
from sqlalchemy import inspect, text

from db.engine import make_engine
from db.migrate import alembic_config, head_revision, open_database

OLD = "0003_withdrawal"


def _old_database(url: str) -> None:
    """A 0003 database with one LCCA and one NOTES trial, as 0003's code wrote them."""
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
            {"design": json.dumps({"tasks": ["lcca", "notes"]}), "now": now},
        )
        conn.execute(
            text(
                'INSERT INTO participants (id, study_id, code, "group", condition_order, '
                "created_at) VALUES (1, 1, 'P001', 'novice', :order, :now)"
            ),
            {"order": json.dumps(["VO", "HV"]), "now": now},
        )
        for trial_id, task, proximal, distal, contacts, summary in (
            (1, "lcca", 0.81, 0.42, 2, {"peak_proximal_reference_force_n": 0.8}),
            (
                2,
                "notes",
                9.5,
                3.25,
                None,
                {"peak_force_rendered_n": 5.6, "push_over_capacity_fraction": 0.21},
            ),
            (3, "lcca", None, None, None, None),  # a trial that never completed
        ):
            conn.execute(
                text(
                    "INSERT INTO trials (id, participant_id, task, condition, block_index, "
                    "trial_index, practice, attempt, status, created_at, peak_proximal_force_n, "
                    "peak_distal_force_n, wall_contacts, summary) VALUES (:id, 1, :task, 'VO', 0, "
                    ":id, false, 1, 'completed', :now, :p, :d, :w, :s)"
                ),
                {
                    "id": trial_id,
                    "task": task,
                    "now": now,
                    "p": proximal,
                    "d": distal,
                    "w": contacts,
                    "s": json.dumps(summary) if summary else None,
                },
            )
    engine.dispose()


def test_old_measures_move_to_their_tasks_names_and_back(db_url: str) -> None:
    _old_database(db_url)
    engine = open_database(db_url, upgrade=True)  # upgrades to the head
    with engine.connect() as conn:
        rows = conn.execute(
            text("SELECT trial_id, name, value FROM trial_measures ORDER BY trial_id, name")
        ).all()
        columns = {c["name"] for c in inspect(conn).get_columns("trials")}
    engine.dispose()
    assert [tuple(r) for r in rows] == [
        (1, "peak_distal_force_n", 0.42),
        (1, "peak_proximal_force_n", 0.81),
        (1, "wall_contacts", 2.0),
        (2, "peak_force_demanded_n", 9.5),
        (2, "peak_force_rendered_n", 5.6),
        (2, "peak_tip_force_n", 3.25),
        (2, "push_over_capacity_fraction", 0.21),
    ]
    assert not {"peak_proximal_force_n", "peak_distal_force_n", "wall_contacts"} & columns

    engine = make_engine(db_url)
    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), OLD)
    with engine.connect() as conn:
        back = conn.execute(
            text(
                "SELECT id, peak_proximal_force_n, peak_distal_force_n, wall_contacts FROM trials "
                "ORDER BY id"
            )
        ).all()
        tables = inspect(conn).get_table_names()
    with engine.begin() as conn:  # and up again, for the next test on this server
        command.upgrade(alembic_config(conn), head_revision())
    engine.dispose()
    assert [tuple(r) for r in back] == [
        (1, 0.81, 0.42, 2),
        (2, 9.5, 3.25, None),
        (3, None, None, None),
    ]
    assert "trial_measures" not in tables
