"""Who is acting: the name written into audit rows and session leases.

`--actor NAME` on the command line, else the `STUDY_ACTOR` environment variable, else
`user@host` from the operating system (every audit row names an actor). The
audit column holds 64 characters; an actor is one printable line of at most that.
"""

from __future__ import annotations

import getpass
import os
import socket

from study.errors import StudyInputError

ACTOR_ENV = "STUDY_ACTOR"
MAX_ACTOR_CHARS = 64


def check_actor(actor: str, source: str = "--actor") -> str:
    """`actor` stripped, or a one-line error naming it and what is expected."""
    value = actor.strip()
    if not value or len(value) > MAX_ACTOR_CHARS or not value.isprintable():
        raise StudyInputError(
            f"{source} {actor!r}; expected 1-{MAX_ACTOR_CHARS} printable characters "
            "(an experimenter code, e.g. EXP02)"
        )
    return value


def current_actor(explicit: str | None = None) -> str:
    """The actor for audit rows: `explicit`, else $STUDY_ACTOR, else user@host."""
    if explicit is not None:
        return check_actor(explicit)
    env = os.environ.get(ACTOR_ENV)
    if env is not None:
        return check_actor(env, ACTOR_ENV)
    try:
        user = getpass.getuser()
    except (KeyError, OSError):  # no passwd entry (containers): the uid says who
        user = f"uid{os.getuid()}" if hasattr(os, "getuid") else "unknown"
    return f"{user}@{socket.gethostname()}"[:MAX_ACTOR_CHARS]
