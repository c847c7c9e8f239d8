"""The one atomic write (`teleop_core.files`): whole or not at all, flushed to disk, the
rename made durable."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from teleop_core.files import atomic_path, write_atomically


def test_a_write_replaces_the_file_whole_and_leaves_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "a.json"
    path.write_text("old")
    write_atomically(path, "new\n")
    assert path.read_text() == "new\n"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_an_error_keeps_the_old_file_and_removes_the_temporary(tmp_path: Path) -> None:
    path = tmp_path / "a.csv"
    path.write_text("old")
    with pytest.raises(RuntimeError, match="disk full"), atomic_path(path) as tmp:
        tmp.write_text("half")
        raise RuntimeError("disk full")
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.csv"]


def test_the_temporary_is_a_sibling_with_the_suffix_asked_for(tmp_path: Path) -> None:
    path = tmp_path / "fig.png"
    with atomic_path(path, suffix=".png") as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".fig.png.")
        assert tmp.suffix == ".png"
        tmp.write_bytes(b"\x89PNG")
    assert path.read_bytes() == b"\x89PNG"


def test_the_file_and_then_its_folder_are_synced(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    synced: list[str] = []
    real = os.fsync

    def fsync(fd: int) -> None:
        synced.append("folder" if stat.S_ISDIR(os.fstat(fd).st_mode) else "file")
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    write_atomically(tmp_path / "b.txt", b"bytes")
    assert synced == ["file", "folder"]
