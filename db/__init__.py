"""The study database: SQLAlchemy 2.x models, engines, Alembic migrations, repositories.

`db` knows nothing of the `study` application (an import-linter contract checks it):
it stores studies, participants, schedules, trials and their samples, NASA-TLX
questionnaires, calibrations and an audit log, on SQLite (embedded default) or
PostgreSQL (multi-site), and upgrades older databases instead of recreating them.
"""

from importlib import import_module
from typing import Any

_EXPORTS = {
    "DatabaseVersionError": "db.errors",
    "DbInputError": "db.errors",
    "MissingDatabaseError": "db.errors",
    "make_engine": "db.engine",
    "make_session_factory": "db.engine",
    "open_database": "db.migrate",
    "resolve_url": "db.engine",
    "write_transaction": "db.engine",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    """The package's names, imported on first use: `db.errors` alone (which every command
    needs for its error lines) does not load SQLAlchemy (0.3 s)."""
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'db' has no attribute {name!r}")
