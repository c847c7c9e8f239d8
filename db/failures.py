"""What went wrong with a database that cannot be used, told apart by cause.

A driver's error names its cause in its own words (SQLite's "database or disk is full",
"attempt to write a readonly database", "database disk image is malformed";
PostgreSQL's "terminating connection due to administrator command", SQLSTATE 53100
"could not extend file"...). `classify` sorts them into the causes a person can act on,
each with what to do: full, read-only, locked, disconnected, corrupt, or unavailable
(none of these: a file that cannot be opened, a server that cannot be reached). The
command line and the session runner both word their one line from it, so the same
fault reads the same wherever it happens.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Failure", "classify"]

_CAUSES: tuple[tuple[str, tuple[str, ...], tuple[str, ...]], ...] = (
    # kind, words of the driver's message, SQLSTATE classes / codes (PostgreSQL)
    ("full", ("full", "no space left", "could not extend", "quota"), ("53",)),
    ("read-only", ("readonly", "read-only", "read only"), ("25006",)),
    ("locked", ("locked", "busy", "lock timeout"), ("55P03",)),
    (
        "disconnected",
        (
            "terminating connection",
            "server closed the connection",
            "connection is closed",
            "the connection is lost",
            "consuming input failed",
            "connection already closed",
            "ssl connection has been closed",
            "connection refused",
            "could not connect",
            "connection timed out",
        ),
        ("08", "57P"),
    ),
    (
        "corrupt",
        ("malformed", "not a database", "corrupt", "file is encrypted", "invalid page"),
        ("XX001", "XX002"),
    ),
)

EXPECTED = {
    "full": "free space: what was committed before stays, the command's own change was not stored",
    "read-only": "a writable database: what only reads (db info, db check, schedule, tlx "
    "show, export, analyze) works on it; nothing of this command was stored",
    "locked": "it free: retry when that program is done, or wait longer with "
    "?timeout=SECONDS in the URL; nothing of this command was stored",
    "disconnected": "a connection that stays up: the server ended it or cannot be reached; "
    "what was committed before stays, retry when the server is back",
    "corrupt": "an intact study database: restore it from its backup (`study db check` "
    "tells what is damaged)",
    "unavailable": "a study database that can be opened and read",
}
"""What was expected instead, per kind, as the end of the one line."""

_SAID = {
    "full": "is full",
    "read-only": "is read-only",
    "locked": "is locked by another program",
    "disconnected": "was disconnected",
    "corrupt": "is damaged",
    "unavailable": "cannot be used",
}


@dataclass(frozen=True)
class Failure:
    """One database fault: its kind and the driver's own first line."""

    kind: str
    """full, read-only, locked, disconnected, corrupt or unavailable."""
    reason: str

    def line(self, shown: str) -> str:
        """`database SHOWN is full (REASON); expected ...`, one line."""
        said, expected = _SAID[self.kind], EXPECTED[self.kind]
        return f"database {shown} {said} ({self.reason}); expected {expected}"


def classify(exc: BaseException) -> Failure:
    """The cause of a database error (a SQLAlchemy `DBAPIError`, or the driver's own).

    Parameters
    ----------
    exc : BaseException
        The error; a wrapped one's driver error (`.orig`) is read.

    Returns
    -------
    Failure
        Its kind (see the module docstring) and the driver's first line.
    """
    orig = getattr(exc, "orig", None) or exc
    text = str(orig).strip()
    reason = text.splitlines()[0] if text else type(orig).__name__
    state = str(getattr(orig, "sqlstate", None) or getattr(orig, "pgcode", None) or "")
    lowered = text.lower()
    if getattr(exc, "connection_invalidated", False):
        return Failure("disconnected", reason)
    for kind, words, states in _CAUSES:
        if (state and state.startswith(states)) or any(w in lowered for w in words):
            return Failure(kind, reason)
    return Failure("unavailable", reason)
