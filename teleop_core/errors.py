"""Errors a caller of the teleoperation core can cause (malformed recording, bad parameter).

They subclass `ValueError` and carry one-line messages naming the bad value and what
was expected, so that the `study` command can print them as they are and exit 2.
"""


class TeleopInputError(ValueError):
    """Input to the teleoperation core that it cannot accept."""
