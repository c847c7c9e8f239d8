"""The schema: migrations match the models, and the database itself refuses bad values."""

from __future__ import annotations

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import Engine, insert, select
from sqlalchemy.exc import IntegrityError

from db.base import Base
from db.engine import make_session_factory
from db.errors import DbInputError
from db.models import TRIAL_STATUSES, Participant, Study, TlxResponse, Trial

RATINGS = {"mental": 50, "physical": 20, "temporal": 35, "performance": 25, "effort": 60}


def _participant(engine: Engine, code: str = "P001") -> int:
    with make_session_factory(engine).begin() as session:
        study = session.scalar(select(Study)) or Study(
            name="s", design_toml="", design={"groups": {}}, seed=1
        )
        p = Participant(study=study, code=code, group="novice", condition_order=["VO", "HV"])
        session.add(p)
        session.flush()
        return p.id


def test_migrations_create_exactly_the_models_schema(engine: Engine) -> None:
    with engine.connect() as conn:
        ctx = MigrationContext.configure(conn, opts={"compare_type": True})
        diff = compare_metadata(ctx, Base.metadata)
    assert diff == []


def test_sqlite_runs_in_wal_mode_with_foreign_keys(sqlite_url: str) -> None:
    from db.migrate import open_database

    engine = open_database(sqlite_url)
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
        assert conn.exec_driver_sql("PRAGMA synchronous").scalar() == 2  # FULL
    engine.dispose()


def test_a_database_opened_not_durable_keeps_wal_without_a_sync_per_commit(
    sqlite_url: str,
) -> None:
    from db.migrate import open_database

    engine = open_database(sqlite_url, durable=False)
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA synchronous").scalar() == 1  # NORMAL
    engine.dispose()
    again = open_database(sqlite_url, create=False)  # the setting is the connection's
    with again.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA synchronous").scalar() == 2
    again.dispose()


def _tlx(pid: int, **overrides: object) -> dict[str, object]:
    return {"participant_id": pid, "task": "lcca", "condition": "HV", **RATINGS, **overrides}


@pytest.mark.parametrize("frustration", [0, 5, 55, 100])
def test_tlx_ratings_on_the_scale_are_stored(engine: Engine, frustration: int) -> None:
    pid = _participant(engine)
    with engine.begin() as conn:
        conn.execute(insert(TlxResponse), _tlx(pid, frustration=frustration))
        stored = conn.scalar(select(TlxResponse.frustration))
    assert stored == frustration


@pytest.mark.parametrize("frustration", [-5, 101, 105, 42, 99])
def test_tlx_ratings_off_the_scale_are_refused_by_the_database(
    engine: Engine, frustration: int
) -> None:
    pid = _participant(engine)
    with pytest.raises(IntegrityError, match="frustration_on_scale"), engine.begin() as conn:
        conn.execute(insert(TlxResponse), _tlx(pid, frustration=frustration))


WEIGHTS_OK = {
    "w_mental": 5,
    "w_physical": 1,
    "w_temporal": 3,
    "w_performance": 2,
    "w_effort": 4,
    "w_frustration": 0,
}


@pytest.mark.parametrize(
    ("weights", "accepted"),
    [
        ({}, True),  # raw TLX only
        (WEIGHTS_OK, True),  # 5+1+3+2+4+0 = 15
        ({**WEIGHTS_OK, "w_frustration": 1}, False),  # sums to 16
        ({**WEIGHTS_OK, "w_mental": 6, "w_physical": 0}, False),  # 6 > 5 wins possible
        ({"w_mental": 5}, False),  # partial
    ],
)
def test_tlx_weights_must_be_complete_tallies_of_15(
    engine: Engine, weights: dict[str, int], accepted: bool
) -> None:
    pid = _participant(engine)
    row = {
        "participant_id": pid,
        "task": "lcca",
        "condition": "VO",
        **RATINGS,
        "frustration": 10,
        **weights,
    }
    if accepted:
        with engine.begin() as conn:
            conn.execute(insert(TlxResponse), row)
    else:
        with pytest.raises(IntegrityError), engine.begin() as conn:
            conn.execute(insert(TlxResponse), row)


def test_one_questionnaire_per_participant_task_condition(engine: Engine) -> None:
    pid = _participant(engine)
    row = {"participant_id": pid, "task": "lcca", "condition": "VO", **RATINGS, "frustration": 0}
    with engine.begin() as conn:
        conn.execute(insert(TlxResponse), row)
    with pytest.raises(IntegrityError), engine.begin() as conn:
        conn.execute(insert(TlxResponse), row)


def _trial(pid: int, **overrides: object) -> dict[str, object]:
    return {
        "participant_id": pid,
        "task": "lcca",
        "condition": "HV",
        "block_index": 0,
        "trial_index": 0,
        **overrides,
    }


def test_trial_status_must_be_known(engine: Engine) -> None:
    pid = _participant(engine)
    with engine.begin() as conn:
        for i, status in enumerate(TRIAL_STATUSES):
            conn.execute(insert(Trial), _trial(pid, status=status, trial_index=i))
    with pytest.raises(IntegrityError, match="status_known"), engine.begin() as conn:
        conn.execute(insert(Trial), _trial(pid, status="done", trial_index=99))


def test_negative_completion_time_is_refused(engine: Engine) -> None:
    pid = _participant(engine)
    with pytest.raises(IntegrityError, match="completion_time_nonneg"), engine.begin() as conn:
        conn.execute(insert(Trial), _trial(pid, completion_time_s=-0.1))


def test_repeated_trial_needs_a_new_attempt_number(engine: Engine) -> None:
    pid = _participant(engine)
    with engine.begin() as conn:
        conn.execute(insert(Trial), _trial(pid, status="interrupted"))
        conn.execute(insert(Trial), _trial(pid, attempt=2))
    with pytest.raises(IntegrityError), engine.begin() as conn:
        conn.execute(insert(Trial), _trial(pid, attempt=2))


def test_foreign_keys_are_enforced(engine: Engine) -> None:
    with pytest.raises(IntegrityError), engine.begin() as conn:
        conn.execute(insert(Trial), _trial(12345))


def test_participant_codes_are_unique_within_a_study(engine: Engine) -> None:
    _participant(engine, "P001")
    with pytest.raises(IntegrityError):
        _participant(engine, "P001")


@pytest.mark.parametrize("code", ["Jane Doe", "p001", "P1", "jane.doe@example.org", ""])
def test_participant_code_must_be_pseudonymous(code: str) -> None:
    with pytest.raises(DbInputError, match="pseudonymous"):
        Participant(code=code, group="novice", condition_order=[])
