"""Reading a researcher's CSV: every problem one line naming the file, the row (as a
spreadsheet numbers it: the header is row 1), the column and what was expected."""

from __future__ import annotations

import csv
import math
import re
import stat
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from study.errors import StudyInputError
from study.protocol.export_files import unescape_cell
from teleop_core.recording_checks import MAX_LINE_BYTES, longest_line_over

DECIMAL = re.compile(r"^[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?$")
WHOLE = re.compile(r"^[+-]?[0-9]+$")


def whole_number(text: str) -> int | None:
    """The whole number `text` spells in ASCII digits (an optional sign), else None:
    Python's `int()` also takes `5_0` and other scripts' digits, which no person means."""
    stripped = text.strip()
    return int(stripped) if WHOLE.match(stripped) else None


@dataclass
class Problems:
    source: str
    items: list[str]

    def add(self, row: int, column: str, message: str) -> None:
        self.items.append(f"{self.source} row {row}, column {column}: {message}")

    def one_of(self, row: int, record: dict, column: str, allowed: Collection[str]) -> bool:
        """Whether `record[column]` is one of `allowed`; adds the problem where not."""
        if record[column] in allowed:
            return True
        self.add(row, column, f"{record[column]!r}; expected one of {', '.join(allowed)}")
        return False

    def raise_if_any(self) -> None:
        if self.items:
            more = f" (and {len(self.items) - 1} more)" if len(self.items) > 1 else ""
            raise StudyInputError(self.items[0] + more)


def read_csv(
    path: Path,
    required: tuple[str, ...],
    optional: tuple[str, ...] = (),
    text_columns: tuple[str, ...] = (),
) -> pd.DataFrame:
    """A CSV of text cells with exactly the `required` and any `optional` columns; the
    `text_columns` unescaped as an export escaped them."""
    if not path.is_file():
        raise StudyInputError(f"{path} does not exist")

    long_line = longest_line_over(path, MAX_LINE_BYTES)
    if long_line is not None:
        raise StudyInputError(
            f"{path} row {long_line}: longer than {MAX_LINE_BYTES} bytes; expected a CSV "
            "of one short row per record"
        )
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, encoding="utf-8")
    except pd.errors.EmptyDataError:
        raise StudyInputError(f"{path} is empty; expected a header row and data rows") from None
    except UnicodeDecodeError as exc:
        raise StudyInputError(
            f"{path} is not UTF-8 text (byte {exc.object[exc.start]:#04x} at offset "
            f"{exc.start}); expected a UTF-8 CSV"
        ) from None
    except (pd.errors.ParserError, OSError) as exc:
        raise StudyInputError(f"{path} is not a readable CSV: {first_line(exc)}") from None
    _check_shape(path)
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise StudyInputError(f"{path} lacks column {missing[0]!r}; expected {', '.join(required)}")
    extra = [c for c in frame.columns if c not in required + optional]
    if extra:
        raise StudyInputError(
            f"{path} has unknown column {extra[0]!r}; expected {', '.join(required + optional)}"
        )
    if frame.empty:
        raise StudyInputError(f"{path} has a header but no rows; expected at least one data row")
    for column in set(text_columns).intersection(frame.columns):
        frame[column] = frame[column].map(unescape_cell)  # an exported file imports back
    return frame


def _check_shape(path: Path) -> None:
    """A header without repeated names, and every row with one field per header column:
    pandas renames a repeated column ('success.1') and shifts a row with extra fields
    into an index, so both are looked at in the file itself."""

    with path.open(newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        header = next(reader, [])
        seen: set[str] = set()
        for name in header:
            if name in seen:
                raise StudyInputError(
                    f"{path} has column {name!r} twice; expected each column once"
                )
            seen.add(name)
        for number, row in enumerate(reader, start=2):
            if row and len(row) != len(header):
                raise StudyInputError(
                    f"{path} row {number}: {len(row)} fields; expected {len(header)}, "
                    "one per header column"
                )


def first_line(exc: BaseException) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def number(
    p: Problems, row: int, col: str, text: str, minimum: float = 0.0, maximum: float = math.inf
) -> float | None:
    """A plain decimal within [minimum, maximum], else a problem naming it."""
    expected = f"a number from {minimum:g} to {maximum:g}"
    if not DECIMAL.match(text.strip()):
        p.add(row, col, f"{text!r} is not a plain decimal number; expected {expected}")
        return None
    value = float(text)
    mantissa = text.strip().lower().split("e")[0]
    if value == 0 and any(c in "123456789" for c in mantissa):
        p.add(row, col, f"{text!r} is too small to store (it would be 0); expected {expected}")
        return None
    if not (math.isfinite(value) and minimum <= value <= maximum):
        p.add(row, col, f"{text!r} is out of range; expected {expected}")
        return None
    return value


BOOL = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}


MAX_TEXT_FILE_BYTES = 10_000_000
"""A design, campaign or model file is a few kB; far past this it is the wrong file."""


def read_text_file(
    path: Path, what: str, expected: str, max_bytes: int = MAX_TEXT_FILE_BYTES
) -> str:
    """The UTF-8 text of the regular file at `path`, read at most `max_bytes` far (a
    device or a named pipe would block or never end), or one line naming the file."""

    try:
        mode = path.stat().st_mode
        if not stat.S_ISREG(mode):
            raise StudyInputError(f"{what} {path} is not a regular file; expected {expected}")
        with path.open("rb") as f:
            raw = f.read(max_bytes + 1)
    except FileNotFoundError:
        raise StudyInputError(f"{what} {path} does not exist; expected {expected}") from None
    except OSError as exc:
        raise StudyInputError(
            f"{what} {path} cannot be read ({exc.strerror or exc}); expected {expected}"
        ) from None
    if len(raw) > max_bytes:
        raise StudyInputError(
            f"{what} {path} is larger than {max_bytes / 1e6:g} MB; expected {expected}"
        )
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise StudyInputError(
            f"{what} {path} is not UTF-8 text (byte {raw[exc.start]:#04x} at offset "
            f"{exc.start}); expected {expected}"
        ) from None
