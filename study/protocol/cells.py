"""Spreadsheet-safe text cells, apart from `export_files` so that a writer of small CSV
files (`study analyze`) loads neither pandas nor pyarrow for them."""

from __future__ import annotations

import re

FORMULA_START = ("=", "+", "-", "@", "\t", "\r")
"""First characters that make a spreadsheet read a cell as a formula (OWASP)."""
_PLAIN_NUMBER = re.compile(r"^[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?$")
_FORMULA_REGEX = "^[=+\\-@\t\r]"
_ESCAPED = re.compile(r"^'[=+\-@\t\r]")


def escape_cell(value: object) -> object:
    """`value` with a leading single quote if it is text a spreadsheet would run.

    >>> escape_cell('=HYPERLINK("http://x")'), escape_cell("-0.5"), escape_cell(-0.5)
    ('\\'=HYPERLINK("http://x")', '-0.5', -0.5)
    """
    if isinstance(value, str) and value.startswith(FORMULA_START):
        if not _PLAIN_NUMBER.match(value):
            return "'" + value
    return value


def unescape_cell(value: str) -> str:
    """Undo `escape_cell` on a cell read back from an exported file."""
    return value[1:] if _ESCAPED.match(value) else value
