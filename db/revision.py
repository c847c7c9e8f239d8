"""The schema revision this version of haptic-study writes, apart from `db.migrate` so
that a reader can check a database's revision without importing SQLAlchemy
(`db.plain`)."""

HEAD_REVISION = "0010_old_layout_chunks"
"""The newest revision in `db/migrations/versions` (kept equal to it by a test)."""
