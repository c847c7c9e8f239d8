"""What the terminal app says when the database (or anything else) fails under a worker.

Textual ends the app on an exception in a worker unless the worker is started with
`exit_on_error=False`; every worker of the app is, and the widget that started it turns
the error into one plain line (`plain_line`) in its status and a notification, so that a
read-only, locked, full, moved or unreachable database never ends the app and nothing
typed on the screen is lost. SQLAlchemy's own message (the SQL, the parameters, a link)
is for a developer, not for the person at the keyboard, so the line names the cause as
the database driver reports it, and what to do.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.exc import DBAPIError, SQLAlchemyError
from textual.worker import Worker, WorkerState

# (what the driver's message contains, what the user reads): the first match wins
_CAUSES = (
    (
        ("readonly", "read-only", "read only"),
        "the database is read-only: nothing was written; open a writable copy of it, or "
        "fix its permissions, and try again",
    ),
    (
        ("database is locked", "lock timeout", "could not obtain lock", "deadlock"),
        "the database is locked by another program: nothing was written; try again when that "
        "program has finished",
    ),
    (
        ("disk is full", "no space left", "diskfull", "disk full"),
        "the disk holding the database is full: nothing more was written; free some space "
        "and try again",
    ),
    (
        (
            "unable to open database",
            "disk i/o error",
            "no such table",
            "malformed",
            "not a database",
        ),
        "the database file cannot be read (moved, deleted or damaged?): nothing was written; "
        "restart `study tui` with the right --db",
    ),
    (
        (
            "could not connect",
            "connection refused",
            "server closed",
            "terminating connection",
            "connection is closed",
            "connection timed out",
            "no route to host",
        ),
        "the database server cannot be reached: nothing was written; check the server and "
        "the network, then try again",
    ),
)


def plain_line(error: BaseException | None) -> str:
    """One line for the status bar: the cause and what to do."""
    if error is None:
        return "the operation failed for an unknown reason"

    if isinstance(error, SQLAlchemyError):
        orig = error.orig if isinstance(error, DBAPIError) else None
        detail = str(orig if orig is not None else error).strip().splitlines()
        text = " ".join(detail).lower()
        for needles, line in _CAUSES:
            if any(n in text for n in needles):
                return line
        if orig is None:  # SQLAlchemy's own error, not the database's: a bug, said so
            first = str(error).split(" (Background on this error")[0].splitlines()[0]
            return f"unexpected {type(error).__name__}: {first}"
        first = detail[0] if detail else type(error).__name__
        return f"the database refused the operation ({first}); nothing was written"
    if isinstance(error, ValueError):  # the project's input errors: already one line
        return str(error).splitlines()[0] if str(error) else type(error).__name__
    if isinstance(error, OSError):
        where = f": {error.filename}" if error.filename else ""
        return f"{error.strerror or error}{where}"
    first = str(error).splitlines()[0] if str(error) else ""
    return f"unexpected {type(error).__name__}{': ' + first if first else ''}"


class SafeWorkers:
    """Mixin for a widget whose workers (started with `exit_on_error=False`) may fail:
    `worker_failed(group, line)` is called with the plain line, which by default is shown
    as an error notification."""

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.state is not WorkerState.ERROR:
            return
        event.stop()
        self.worker_failed(event.worker.group, plain_line(event.worker.error))

    def worker_failed(self, group: str, line: str) -> None:
        app: Any = self.app  # type: ignore[attr-defined]
        app.notify(line, severity="error", timeout=15)
