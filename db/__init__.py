"""The study database: SQLAlchemy 2.x models, engines, Alembic migrations, repositories.

`db` knows nothing of the `study` application (an import-linter contract checks it):
it stores studies, participants, schedules, trials and their samples, NASA-TLX
questionnaires, calibrations and an audit log, on SQLite (embedded default) or
PostgreSQL (multi-site), and upgrades older databases instead of recreating them.
"""
