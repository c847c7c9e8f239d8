"""Export files that are safe to open in a spreadsheet and never half-written.

This module owns how `study export` puts a file on disk, so the rule lives in one place
for the trials, TLX, codebook and samples files:

- **Formula-like text is escaped, at export.** A text cell that starts with `=`, `+`,
  `-`, `@`, a tab or a carriage return gets a single quote in front (OWASP, "CSV
  Injection"), so a spreadsheet shows it as text instead of running it: a group named
  `=HYPERLINK(...)` in the design is exported as `'=HYPERLINK(...)`. Numbers are left
  alone: a float column is never text, and a text cell that is a plain decimal (`-0.5`)
  is a number to a spreadsheet too, not a formula. Escaping at export rather than
  refusing such names at entry also covers databases written before this rule and
  names that come from a design file; `study import` removes the quote again
  (`unescape_cell`), so an exported file imports back as it was. Parquet files keep
  the text verbatim (no spreadsheet opens them).
- **Replaced atomically.** A file is written under a temporary name in its own
  directory (created exclusively, so never through a planted link), flushed to disk
  (`fsync`), and renamed over the target with `os.replace`; an error or an interrupt
  leaves the previous file as it was and no temporary file behind.
- **Never through a symbolic link.** A target that is a symbolic link is refused with
  one line naming it (`ExportTargetError`, exit status 2); the file the link points to
  is not touched.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING

import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from study.errors import StudyInputError
from study.protocol.cells import (
    _FORMULA_REGEX,
    _PLAIN_NUMBER,
    escape_cell,
)
from study.protocol.cells import (
    FORMULA_START as FORMULA_START,
)
from study.protocol.cells import unescape_cell as unescape_cell
from teleop_core.files import replace_durably, temp_sibling

if TYPE_CHECKING:
    import pyarrow.parquet as pq


class ExportTargetError(StudyInputError):
    """An export target that must not be written (a symbolic link)."""


def escape_frame(frame: pd.DataFrame) -> pd.DataFrame:
    """A copy of `frame` with every text cell passed through `escape_cell`."""
    out = frame.copy()
    for column in out.columns:
        if out[column].dtype == object or pd.api.types.is_string_dtype(out[column]):
            out[column] = out[column].map(escape_cell)
    return out


def escape_array(values: pa.Array) -> pa.Array:
    """`escape_cell` over a pyarrow string array (numbers and nulls pass unchanged)."""
    if not pa.types.is_string(values.type) and not pa.types.is_large_string(values.type):
        return values
    risky = pc.and_(
        pc.match_substring_regex(values, _FORMULA_REGEX),
        pc.invert(pc.match_substring_regex(values, _PLAIN_NUMBER.pattern)),
    )
    if not pc.any(risky).as_py():
        return values
    quoted = pc.binary_join_element_wise(pa.scalar("'", values.type), values, "")
    return pc.if_else(risky, quoted, values)


def refuse_symlink(path: Path) -> None:
    """Raise `ExportTargetError` if `path` is a symbolic link (dangling or not)."""
    if path.is_symlink():
        raise ExportTargetError(
            f"{path} is a symbolic link; expected a regular file or no file there "
            "(an export never writes through a link)"
        )


class AtomicFile:
    """A binary file written as a temporary sibling of `path`, renamed over it on commit.

    `commit()` flushes it to disk and replaces `path` in one step; `abort()` removes it.
    """

    def __init__(self, path: Path) -> None:
        refuse_symlink(path)
        self.path = path
        fd, self.tmp = temp_sibling(path)
        self.file: IO[bytes] = os.fdopen(fd, "wb")

    def _finish(self) -> None:
        if not self.file.closed:
            self.file.close()

    def commit(self) -> Path:
        self._finish()
        refuse_symlink(self.path)  # made a link while we wrote: still not through it
        return replace_durably(self.tmp, self.path)

    def abort(self) -> None:
        try:
            self.file.close()
        finally:
            self.tmp.unlink(missing_ok=True)


class StagedTableFile:
    """A Parquet or CSV file of `schema` written part by part into an `AtomicFile`,
    renamed to its name on commit; use as a context manager (an error removes it).

    Parquet parts are tables (one row group each; `text_columns` dictionary-encoded),
    CSV parts the text of their rows (the header is written here).
    """

    def __init__(
        self, path: Path, fmt: str, schema: pa.Schema, text_columns: Sequence[str] = ()
    ) -> None:
        self.path = path
        self._out = AtomicFile(path)
        self.tmp = self._out.tmp
        self.rows = 0
        self._parquet: pq.ParquetWriter | None = None
        self._sink: pa.NativeFile | None = None
        if fmt == "parquet":
            # pyarrow's own file on the staged path, not the Python file object: through
            # a Python file every write of the encoder takes the GIL back, and the reader
            # threads then wait for it (the sample export ran on one core: 15 s for
            # 10,000,000 samples, 13 of them in `write_table`). The staged file's descriptor still
            # flushes the data to disk on commit (fsync is per file, not per descriptor).
            self._sink = pa.BufferedOutputStream(pa.OSFile(str(self.tmp), "wb"), 1 << 20)
            import pyarrow.parquet as pq  # here: `study import` reads this module too

            self._parquet = pq.ParquetWriter(
                self._sink, schema, compression="snappy", use_dictionary=list(text_columns)
            )
        else:
            # The header as pandas wrote it (unquoted); values quoted where pyarrow needs.
            self._out.file.write((",".join(schema.names) + "\n").encode())
        self._closed = False

    def write(self, part: tuple[int, pa.Table | pa.Buffer]) -> None:
        """One part: (rows, a table (Parquet: one row group) or its CSV text)."""
        rows, data = part
        self.rows += rows
        if isinstance(data, pa.Table):
            if self._parquet is not None and rows:
                self._parquet.write_table(data, row_group_size=rows)
        else:
            self._out.file.write(data)

    def __enter__(self) -> StagedTableFile:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *_: object) -> None:
        if exc_type is not None:  # whatever stopped it, no partial file is left
            self.abort()

    def commit(self) -> Path:
        self._close()
        return self._out.commit()

    def abort(self) -> None:
        try:
            self._close()
        finally:
            self._out.abort()

    def _close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._parquet is not None:
                self._parquet.close()
            if self._sink is not None:
                self._sink.close()
