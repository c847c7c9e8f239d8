"""The free text a person types into the study: notes, session notes and reasons.

Each is one line of at most `MAX_TEXT_CHARS` printable characters (a newline, a tab or a
terminal's escape sequence would garble every listing and the audit log), with its runs
of spaces collapsed. The database holds pseudonymous codes and no personal data, so a
text that looks like contact details is refused with a line saying why: an e-mail
address (`name@host.tld`, the name and host in any script, `name [at] host [dot] tld`
too) or a phone number (seven or more digits, written with the spaces, dots, dashes,
slashes, brackets and leading `+` or `00` people put in them). Dates, timestamps
(20251202-1030), times of day and decimal numbers are no phone numbers and are not
counted (`NOT_PHONE`): "force 12.5 N at 3-4 s" is kept. A text that only looks like
contact details (a device's serial or lot number, an IP address) is kept when the caller
says so (`keep_lookalike`, or a `NotPersonal` text; on the command line
`--not-personal`), and the audit log then shows it as the person typed it.

Names cannot be told from other words without a list of names, and are not looked for:
the rule "codes only" is the experimenter's, and `study` states it in its help.
"""

from __future__ import annotations

import re

from study.errors import StudyInputError, quoted

MAX_TEXT_CHARS = 500

EMAIL = re.compile(
    r"[\w.%+'-]+"  # the local part, in any script (jürgen.müller, 用户, a.b+c)
    r"(?:@|\s*[\[({]\s*at\s*[\])}]\s*)"  # @, or a written-out [at] / (at)
    r"[^\W_](?:[\w-]*[^\W_])?"  # the host's first label
    r"(?:(?:\.|\s*[\[({]\s*dot\s*[\])}]\s*)[^\W_](?:[\w-]*[^\W_])?)*"  # sub., co.
    r"(?:\.|\s*[\[({]\s*dot\s*[\])}]\s*)[^\W\d_]{2,}",  # the top-level domain, letters
    re.IGNORECASE,
)
PHONE = re.compile(r"(?<![\w.])\+?(\(?\d[\d ()./-]{5,}\d)(?![\w])")
MIN_PHONE_DIGITS = 7
"""Fewer digits than any phone number with its area code (a trial count, a year)."""
NOT_PHONE = re.compile(
    r"(?<![\d.])(?:"
    r"(?:19|20)\d\d([-./])\d{1,2}\1\d{1,2}"  # a date, 1999-12-02, 2025/12/02
    r"|\d{1,2}([./])\d{1,2}\2(?:19|20)\d\d"  # a date, 02.12.2025, 2/12/2025
    r"|(?:19|20)\d{6}[-T_]\d{4,6}"  # a timestamp, 20251202-1030
    r"|\d{1,2}:\d\d(?::\d\d)?"  # a time of day, 10:30, 10:30:15
    r"|\d+[.,]\d+"  # a decimal number, 12.5 or 12,5, not part of a dotted chain
    r")(?!\d|\.\d)"
)
"""What holds many digits and is no phone number: dates, timestamps, times of day and
decimal numbers, taken out of the text before phone numbers are looked for (so "force
12.5 N 3.75 N" or "02.12.2025 10:30" is no phone number)."""

OPT_OUT = "--not-personal"
"""The command-line flag that keeps a text which only looks like contact details."""


class NotPersonal(str):
    """A text the person confirmed only looks like contact details (`--not-personal`):
    `check_free_text` keeps it."""


class PersonalDataError(StudyInputError):
    """A free text that looks like personal data (an e-mail address, a phone number).
    The message names no flag: the command line adds `OPT_OUT` (`study.commands.base`),
    the terminal app has no way to keep such a text."""


def looks_personal(text: str) -> str | None:
    """What in `text` looks like contact details ("an e-mail address 'a@b.org'"), or None."""
    email = EMAIL.search(text)
    if email:
        return f"an e-mail address {email.group(0)!r}"
    masked = NOT_PHONE.sub(";", text)
    for match in PHONE.finditer(masked):
        digits = sum(c.isdigit() for c in match.group(0))
        if digits >= MIN_PHONE_DIGITS:
            return f"a phone number {match.group(0).strip()!r}"
    return None


def check_free_text(what: str, text: str, *, keep_lookalike: bool = False) -> str:
    """`text` as it is stored: one printable line of 1 to `MAX_TEXT_CHARS` characters,
    its spaces collapsed, with nothing that looks like contact details (unless
    `keep_lookalike`); else StudyInputError naming it.

    Parameters
    ----------
    what : str
        What the text is, for the message ("note", "withdrawal reason").
    text : str
        What was typed.
    keep_lookalike : bool, optional
        Keep a text that only looks like an e-mail address or a phone number (so is a
        `NotPersonal` text).

    Returns
    -------
    str
        The text to store.

    Raises
    ------
    StudyInputError
        Control characters, empty, too long; `PersonalDataError` for contact details.
    """
    shown = quoted(text)
    if not text.isprintable():  # a newline, a tab, a terminal's escape sequence
        raise StudyInputError(
            f"{what} {shown} holds control characters; expected 1-{MAX_TEXT_CHARS} "
            "printable characters on one line"
        )
    value = " ".join(text.split())
    if not value or len(value) > MAX_TEXT_CHARS:
        raise StudyInputError(
            f"{what} {shown} ({len(value)} characters); expected 1-{MAX_TEXT_CHARS} "
            "characters of text"
        )
    kept = keep_lookalike or isinstance(text, NotPersonal)
    found = None if kept else looks_personal(value)
    if found is not None:
        raise PersonalDataError(
            f"{what} holds what looks like {found}; expected no personal data (participants "
            "are pseudonymous codes): leave contact details out"
        )
    return value
