"""Opening databases: create when empty, upgrade when older, refuse what is unknown."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import inspect, select, text

from db.engine import make_engine, make_session_factory
from db.errors import DatabaseVersionError, MissingDatabaseError, NotAStudyDatabaseError
from db.migrate import (
    HEAD_REVISION,
    SchemaState,
    head_revision,
    inspect_database,
    open_database,
)
from db.models import Study

NEXT_REVISION = '''
"""test-only: a later revision that adds a column to studies"""
import sqlalchemy as sa
from alembic import op

revision = "9001"
down_revision = "{head}"
branch_labels = None
depends_on = None


def upgrade():
    with op.batch_alter_table("studies") as batch_op:
        batch_op.add_column(sa.Column("note", sa.Text(), nullable=True))


def downgrade():
    with op.batch_alter_table("studies") as batch_op:
        batch_op.drop_column("note")
'''


@pytest.fixture
def later_revision(tmp_path: Path) -> Path:
    """A folder holding one revision newer than the installed head."""
    folder = tmp_path / "later_versions"
    folder.mkdir()
    (folder / "9001_add_note.py").write_text(NEXT_REVISION.format(head=head_revision()))
    return folder


def _revision(url: str) -> str | None:
    engine = make_engine(url)
    with engine.connect() as conn:
        rows = conn.execute(text("SELECT version_num FROM alembic_version")).scalars().all()
    engine.dispose()
    assert len(rows) == 1
    return rows[0]


def test_empty_database_is_created_at_the_newest_revision(db_url: str) -> None:
    engine = open_database(db_url)
    engine.dispose()
    assert _revision(db_url) == head_revision()
    assert inspect_database(db_url).state is SchemaState.CURRENT


def test_older_database_is_upgraded_in_place_keeping_its_data(
    db_url: str, later_revision: Path
) -> None:
    engine = open_database(db_url)
    with make_session_factory(engine).begin() as session:
        session.add(Study(name="pilot", design_toml="x = 1", design={"x": 1}, seed=7))
    engine.dispose()

    reports: list[tuple[str | None, str, Path | None]] = []
    engine = open_database(
        db_url,
        upgrade=True,
        version_locations=[later_revision],
        on_upgrade=lambda *r: reports.append(r),
    )
    with engine.connect() as conn:
        columns = {c["name"] for c in inspect(conn).get_columns("studies")}
        names = conn.execute(text("SELECT name, seed FROM studies")).all()
    engine.dispose()

    assert _revision(db_url) == "9001"
    assert "note" in columns
    assert names == [("pilot", 7)]
    before, after, backup = reports[0]
    assert (before, after) == (head_revision(), "9001")
    if db_url.startswith("sqlite"):
        # The file as it was before the upgrade is kept beside it.
        assert backup is not None
        assert backup.name.endswith(f".before-{head_revision()}.bak")
        old = make_engine(f"sqlite:///{backup}")
        with old.connect() as conn:
            assert conn.execute(select(Study.name)).scalars().all() == ["pilot"]
            assert "note" not in {c["name"] for c in inspect(conn).get_columns("studies")}
        old.dispose()


def test_database_from_a_newer_version_is_refused_and_left_alone(
    db_url: str, later_revision: Path
) -> None:
    open_database(db_url, version_locations=[later_revision]).dispose()
    with pytest.raises(DatabaseVersionError, match=r"revision '9001'.*upgrade haptic-study"):
        open_database(db_url)
    assert _revision(db_url) == "9001"


def test_foreign_database_is_refused_not_recreated(db_url: str) -> None:
    engine = make_engine(db_url)
    with engine.begin() as conn:
        conn.execute(text("CREATE TABLE lab_notes (id INTEGER PRIMARY KEY, body TEXT)"))
        conn.execute(text("INSERT INTO lab_notes VALUES (1, 'keep me')"))
    engine.dispose()
    with pytest.raises(NotAStudyDatabaseError, match="no haptic-study schema revision"):
        open_database(db_url)
    engine = make_engine(db_url)
    with engine.connect() as conn:
        assert conn.execute(text("SELECT body FROM lab_notes")).scalar() == "keep me"
        assert "studies" not in inspect(conn).get_table_names()
    engine.dispose()


def test_missing_sqlite_file_is_not_created_when_not_asked(tmp_path: Path) -> None:
    path = tmp_path / "absent.db"
    with pytest.raises(MissingDatabaseError, match=r"absent\.db"):
        open_database(str(path), create=False)
    assert not path.exists()


def test_inspection_does_not_create_or_change_anything(tmp_path: Path) -> None:
    path = tmp_path / "absent.db"
    with pytest.raises(MissingDatabaseError):
        inspect_database(str(path))
    assert not path.exists()


_OPEN_SCRIPT = """
import sys
from db.migrate import open_database
open_database(sys.argv[1]).dispose()
"""


def test_two_processes_creating_one_database_at_once_both_succeed(db_url: str) -> None:
    """Two lab machines starting at the same moment: the write lock serialises creation."""
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _OPEN_SCRIPT, db_url],
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    errors = [p.communicate(timeout=120)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], errors
    assert _revision(db_url) == head_revision()


def test_the_head_constant_is_the_head_of_the_shipped_scripts() -> None:
    # open_database trusts HEAD_REVISION to skip importing Alembic on a current database;
    # Alembic's own ScriptDirectory is the reference.
    assert HEAD_REVISION == head_revision()


def test_a_current_database_opens_without_importing_alembic(tmp_path: Path) -> None:
    db_file = tmp_path / "s.db"
    open_database(str(db_file)).dispose()
    code = (
        "import sys; from db.migrate import open_database; "
        f"open_database({str(db_file)!r}, create=False).dispose(); "
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'alembic'))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
