"""Alembic environment for the study database.

`db.migrate` passes an open connection in `config.attributes["connection"]` (inside a
transaction holding the write lock); the `alembic` command line is not used.
"""

from alembic import context
from sqlalchemy import Connection

import db.models  # noqa: F401  (registers every table on Base.metadata)
from db.base import Base

config = context.config


def _run(connection: Connection) -> None:
    context.configure(
        connection=connection,
        target_metadata=Base.metadata,
        render_as_batch=True,
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


connection = config.attributes.get("connection")
if connection is None:
    raise RuntimeError("db.migrate passes a connection; the alembic command line is not supported")
_run(connection)
