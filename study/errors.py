"""Errors a user of the `study` application can cause (bad design file, unknown participant...).

Like `db.errors.DbInputError` and `teleop_core.errors.TeleopInputError`, each message is
one line naming the bad value and what was expected; `study.cli` prints it and exits 2.
"""


class StudyInputError(ValueError):
    """Input to the study application that it cannot accept."""


class ReasonNeeded(StudyInputError):
    """A change that needs a reason for the audit log was given none. The message names
    no way to give one: the command line adds its flag, the app has its own field."""


QUOTE_CHARS = 40
"""At most this many characters of a refused value are quoted in its message."""


def quoted(value: object, limit: int = QUOTE_CHARS) -> str:
    """`value` as a message quotes it (its repr), cut to `limit` characters with an
    ellipsis: a pasted page, or a number of 300 digits, names itself in one line."""
    if isinstance(value, str):
        return repr(value if len(value) <= limit else value[: limit - 1] + "\u2026")
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "\u2026"
