"""Errors a user of the `study` application can cause (bad design file, unknown participant...).

Like `db.errors.DbInputError` and `teleop_core.errors.TeleopInputError`, each message is
one line naming the bad value and what was expected; `study.cli` prints it and exits 2.
"""


class StudyInputError(ValueError):
    """Input to the study application that it cannot accept."""


QUOTED_CHARS = 40
"""The most of an offending value a message quotes (300 pasted digits filled half of an
80 x 24 screen)."""


def quoted(value: object, limit: int = QUOTED_CHARS) -> str:
    """`value` as a message quotes it: its repr, cut to its first `limit` characters and
    "…" when it is longer (the value's own length is said where it matters).

    Examples
    --------
    >>> quoted("abc")
    "'abc'"
    >>> quoted("1" * 300, 5)
    "'11111…'"
    """
    text = value if isinstance(value, str) else str(value)
    if len(text) <= limit:
        return repr(value) if isinstance(value, str) else text
    return repr(text[:limit] + "…")
