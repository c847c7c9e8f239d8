"""Files written whole or not at all: the one atomic write of the project.

A file is written as a temporary sibling (same folder, so the rename cannot cross a
file system), flushed to disk (`fsync` of the file), renamed over the target with
`os.replace` (atomic on POSIX and Windows), and the rename made durable (`fsync` of the
folder). An error or an interrupt before the rename leaves the previous file as it was
and removes the temporary one; a power loss after it leaves the new one.

The standard library has the pieces (`tempfile.mkstemp`, `os.replace`, `os.fsync`) but
no function that puts them together, and the few packages that do (atomicwrites,
archived) would be a dependency for twenty lines. It lives in `teleop_core`, the lowest
layer, because the control loop's compiled kernels and the recordings are written this
way too; `study` and its commands use the same functions.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_path", "fsync_dir", "replace_durably", "temp_sibling", "write_atomically"]


def temp_sibling(path: Path, suffix: str = ".partial") -> tuple[int, Path]:
    """A new temporary file beside `path` (`.NAME.XXXX<suffix>`): its descriptor and path.

    `suffix` ends the temporary name (a writer such as matplotlib's `savefig` picks its
    format from it).
    """
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    return fd, Path(name)


def fsync_dir(folder: Path) -> None:
    """Make a rename in `folder` durable (POSIX); a no-op where directories cannot be
    opened or synced (some file systems refuse; the rename still happened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def replace_durably(tmp: Path, path: Path) -> Path:
    """Flush `tmp` to disk, rename it over `path` and make the rename durable; `path`."""
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    fsync_dir(path.parent)
    return path


@contextmanager
def atomic_path(path: Path, suffix: str = ".partial") -> Iterator[Path]:
    """A temporary path to write `path`'s content to; renamed over `path` (durably) when
    the block ends without an error, removed when it raises.

    Examples
    --------
    >>> with atomic_path(Path("fig.png"), suffix=".png") as tmp:   # doctest: +SKIP
    ...     figure.savefig(tmp)
    """
    path = Path(path)
    fd, tmp = temp_sibling(path, suffix)
    os.close(fd)
    try:
        yield tmp
        replace_durably(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_atomically(path: Path, data: str | bytes, encoding: str = "utf-8") -> Path:
    """Write `data` (text in `encoding`, or bytes) to `path` whole or not at all."""
    with atomic_path(Path(path)) as tmp:
        if isinstance(data, bytes):
            tmp.write_bytes(data)
        else:
            tmp.write_text(data, encoding=encoding)
    return Path(path)
