"""Errors a user can cause at the database layer.

Each one's message is a single line naming the bad value and what was expected; the
`study` command prints it and exits with status 2. They subclass `ValueError` so that
library callers can catch them without importing this package.
"""


class DbInputError(ValueError):
    """A database URL, file or value that the study database cannot accept."""


class DatabaseVersionError(DbInputError):
    """The database's schema revision is unknown to this version of haptic-study."""


class NotAStudyDatabaseError(DbInputError):
    """The database holds tables but no haptic-study schema revision."""


class MissingDatabaseError(DbInputError):
    """No database exists at the given location and creating one was not asked for."""


class DatabaseGoneError(OSError):
    """The SQLite file an open engine uses was deleted, moved or replaced meanwhile.

    Not a `DbInputError`: nothing the user typed was wrong, and code that turns a
    `ValueError` into "refused: ..." must not mistake it for a bad value. `study`
    commands print it as one line all the same (it is among their user errors)."""


class OutdatedDatabaseError(DbInputError):
    """The database is at an older schema revision; only `study db upgrade` upgrades it."""
