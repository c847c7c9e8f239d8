"""Errors a user of the `study` application can cause (bad design file, unknown participant...).

Like `db.errors.DbInputError` and `teleop_core.errors.TeleopInputError`, each message is
one line naming the bad value and what was expected; `study.cli` prints it and exits 2.
"""


class StudyInputError(ValueError):
    """Input to the study application that it cannot accept."""


class ReasonNeeded(StudyInputError):
    """A change that needs a reason for the audit log was given none. The message names
    no way to give one: the command line adds its flag, the app has its own field."""
