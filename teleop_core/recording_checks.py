"""What every CSV recording contract checks before anything is computed from it.

The follower (`teleop_core.follower.recording`), the master's calibration, the NOTES
bench (`teleop_core.notes.recording`) and any drive's rigid-axis recording
(`teleop_core.calibration.rigid_axis`) each have their own columns, but a file that is
not a recording at all must be refused the same way by all of them, with
one line naming the file, the line (the CSV's line number: the header is line 1), the
column, the value and what was expected, before `study calibrate`, `study estimator`
or `study identify` writes anything:

- a readable UTF-8 CSV file with a header of distinct column names;
- every cell a finite plain number (`pandas.to_numeric`: no `nan`, `inf`, `1e400`,
  `3_0`, `0x10`) of magnitude at most `MAX_ABS_VALUE` (SI units: `1e300` is corruption,
  not a measurement, and would overflow the fits' squares);
- lines of at most `MAX_LINE_BYTES` (a file of one endless line is no CSV);
- time strictly increasing (a repeated time is named as such), at least the contract's
  minimum number of rows, and a median sampling rate from `MIN_RATE_HZ` to
  `MAX_RATE_HZ` (a time column in ms or in µs read as seconds lands outside it);
- for a recording a model is fitted to (`calibrate`, `estimator train`, `identify`),
  signals that vary, by at least `MIN_SPREAD` (`check_varies`: an all-zero file has
  nothing to fit, a file scaled by 1e-300 underflows the fits' squares). Not for
  `estimator run`, whose load cell may well read a constant.

The contract modules keep their own error classes (each a `TeleopInputError`) and
pass them in, so callers catching `RecordingError` or `NotesRecordingError` still do.
"""

from __future__ import annotations

import csv
import stat
from pathlib import Path

import numpy as np
import pandas as pd

from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError

MAX_ABS_VALUE = 1e12
"""Largest magnitude of any cell, SI units: far beyond any bench signal (and a Unix time
stamp, 1.7e9 s), far below where squares overflow."""
MIN_RATE_HZ = 10.0
"""Slowest median sampling rate, Hz: a 1 kHz log whose time is in ms gives 1 Hz."""
MAX_RATE_HZ = 1e6
"""Fastest median sampling rate, Hz: beyond any bench's data logger (time in µs read as
seconds gives 1e6 times the true rate)."""

MIN_SPREAD = 1e-100
"""Smallest range (max - min) of a signal a model is fitted to, SI units: far below any
bench signal, far above where the fits' squares underflow to 0 (a recording scaled by
1e-300 gave a zero RMSE to divide by). A single cell may be nearer 0: a simulated speed
decays to 1e-102."""
MAX_LINE_BYTES = 65_536
"""Longest line: a few hundred columns at most; a file of one endless line is no
recording (pandas would split it into millions of fields)."""

ErrorType = type[TeleopInputError]


def read_cells(path: str | Path, error: ErrorType) -> pd.DataFrame:
    """The CSV at `path` as text cells with stripped, distinct column names."""
    path = Path(path)
    _check_header_length(path, error)
    try:
        frame = pd.read_csv(
            path, dtype=str, keep_default_na=False, skipinitialspace=True, encoding="utf-8"
        )
    except FileNotFoundError:
        raise error(f"recording {path}: no such file; expected a CSV file") from None
    except pd.errors.EmptyDataError:
        raise error(f"recording {path} is empty; expected a header row and data") from None
    except UnicodeDecodeError as exc:
        raise error(
            f"recording {path} is not UTF-8 text (byte {exc.object[exc.start]:#04x} at "
            f"offset {exc.start}); expected a UTF-8 CSV file"
        ) from None
    except (pd.errors.ParserError, OSError, ValueError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise error(f"recording {path} is not a readable CSV file: {first}") from None
    names = _header(path)
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise error(
                f"recording {path}, line 1: column {name!r} appears twice; expected "
                "distinct column names"
            )
        seen.add(name)
    frame.columns = [str(c).strip() for c in frame.columns]
    return frame


def _check_header_length(path: Path, error: ErrorType) -> None:
    """Refuse a file that is not a regular file (a named pipe never ends), or with a
    line longer than `MAX_LINE_BYTES`, before pandas reads it (pandas would spend minutes
    splitting one endless line into millions of fields)."""

    try:
        if not stat.S_ISREG(path.stat().st_mode):
            raise error(f"recording {path} is not a readable CSV file: not a regular file")
        line = longest_line_over(path, MAX_LINE_BYTES)
    except FileNotFoundError:
        raise error(f"recording {path} does not exist; expected a CSV file") from None
    except OSError as exc:
        raise error(f"recording {path} cannot be read ({exc.strerror or exc})") from None
    if line is not None:
        raise error(
            f"recording {path}, line {line}: longer than {MAX_LINE_BYTES} bytes; expected a "
            "header of column names and one line per sample"
        )


def longest_line_over(path: Path, limit: int, block_bytes: int = 1 << 22) -> int | None:
    """The number (from 1) of the first line of `path` longer than `limit` bytes, or
    None. Read in blocks, the line breaks found by numpy: a few ms per 10 MB."""
    run, line = 0, 1  # bytes of the current line so far, its number
    with path.open("rb") as f:
        while block := f.read(block_bytes):
            data = np.frombuffer(block, np.uint8)
            breaks = np.flatnonzero((data == 10) | (data == 13))
            if not len(breaks):
                run += len(block)
                if run > limit:
                    return line
                continue
            # the lengths of the lines that end in this block (the first one started before)
            ends = np.concatenate(([breaks[0] + run], np.diff(breaks) - 1))
            over = np.flatnonzero(ends > limit)
            if len(over):
                return line + int(np.count_nonzero(data[breaks[: over[0]]] == 10))
            line += int(np.count_nonzero(data[breaks] == 10))
            run = len(block) - int(breaks[-1]) - 1
    return line if run > limit else None


def _header(path: Path) -> list[str]:
    """The header's names as written (pandas renames a repeated `t` to `t.1`)."""
    with open(path, newline="", encoding="utf-8") as f:
        first = next(csv.reader(f), [])
    return [name.strip() for name in first]


def numbers(
    frame: pd.DataFrame,
    column: str,
    source: str,
    error: ErrorType,
    row_word: str = "line",
    first_row: int = 2,
) -> Float1D:
    """`frame[column]` as floats; one line naming the first cell that is not a finite
    plain number within `MAX_ABS_VALUE` (its row counted from `first_row`: a CSV's
    first data line is line 2)."""
    raw = frame[column]
    values = pd.to_numeric(raw.astype(str).str.strip(), errors="coerce").to_numpy(float)
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(~np.isfinite(values) | (np.abs(values) > MAX_ABS_VALUE))
    if bad.size:
        row = int(bad[0])
        cell = raw.iloc[row] if isinstance(raw.iloc[row], str) else str(raw.iloc[row])
        if pd.isna(raw.iloc[row]):
            cell = ""  # a short row: the cell is missing
        what = (
            f"is beyond ±{MAX_ABS_VALUE:g}; expected a value in SI units"
            if np.isfinite(values[row])
            else "is not a finite number; expected a plain decimal number"
        )
        raise error(f"{source}, {row_word} {row + first_row}, column {column!r}: {cell!r} {what}")
    return values


def check_time(
    t: Float1D, source: str, error: ErrorType, min_rows: int, row_word: str = "line"
) -> None:
    """Enough rows, `t` strictly increasing, a plausible median sampling rate."""
    if len(t) < min_rows:
        raise error(f"{source} has {len(t)} data rows; expected at least {min_rows}")
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if back.size:
        k = int(back[0]) + 1
        how = "repeats" if t[k] == t[k - 1] else "does not come after"
        raise error(
            f"{source}, {row_word} {k + 2}, column 't': {float(t[k])!r} {how} "
            f"{float(t[k - 1])!r} on the {row_word} before; expected strictly increasing times"
        )
    if len(step):
        median = float(np.median(step))
        rate = 1.0 / median  # > 0: the steps are
        if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
            raise error(
                f"{source}, column 't', {row_word}s 2-{len(t) + 1}: median step {median:g} s "
                f"({rate:g} Hz); expected a sampling rate from {MIN_RATE_HZ:g} Hz to "
                f"{MAX_RATE_HZ:g} Hz with t in seconds"
            )


def check_varies(
    values: dict[str, Float1D], columns: tuple[str, ...], source: str, error: ErrorType
) -> None:
    """Refuse a recording to fit a model to whose signal `columns` never change (an
    all-zero file, a sensor left unplugged): the fit has nothing to go on, and its
    variance-based steps would divide by zero."""
    for column in columns:
        v = values[column]
        if len(v) and float(np.max(v)) == float(np.min(v)):
            raise error(
                f"{source}, column {column!r}: {float(v[0])!r} on every line; expected a "
                "signal that varies (a recording that excites the model)"
            )
        spread = float(np.max(v) - np.min(v)) if len(v) else 0.0
        if len(v) and spread < MIN_SPREAD:
            raise error(
                f"{source}, column {column!r}: varies by only {spread:.3g}; expected a signal "
                f"in SI units varying by at least {MIN_SPREAD:g} (its squares underflow to 0)"
            )
