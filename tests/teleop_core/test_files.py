"""The one atomic write (`teleop_core.files`): whole or not at all, flushed to disk, the
rename made durable."""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

import pytest

import teleop_core.files
from teleop_core.files import atomic_path, write_atomically

ROOT = Path(__file__).resolve().parents[2]
HAND_MADE = re.compile(
    r"\bos\.(replace|rename)\(|\bmkstemp\(|NamedTemporaryFile\(|\btmp\w*\.(replace|rename)\("
)
"""The pieces of a hand-made atomic write: a rename over the target, a temporary file."""
RENAMED_BY_HAND = {
    "teleop_core/estimation/model.py": "a model folder written whole: a folder, not a file",
}
"""The modules that rename something into place themselves, and why."""


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
        assert tmp.parent == tmp_path
        assert tmp.name.startswith(".fig.png.")
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


@pytest.mark.parametrize(
    ("line", "found"),
    [
        ("    os.replace(tmp, path)", True),
        ("    tmp.replace(json_path)", True),
        ("    tmp_png.rename(png)", True),
        ('    fd, tmp = tempfile.mkstemp(prefix=".tui-", dir=path.parent)', True),
        ('    name = name.replace("-", "_")', False),
        ("    with atomic_path(path) as tmp:", False),
    ],
)
def test_the_hand_made_pattern_finds_what_it_should(line: str, found: bool) -> None:
    assert bool(HAND_MADE.search(line)) is found


def test_no_module_writes_atomically_by_hand() -> None:
    """Every atomic write of a file goes through `teleop_core.files`: none of the
    project's other modules renames a temporary file over its target itself."""
    own = Path(teleop_core.files.__file__).resolve().relative_to(ROOT).as_posix()
    hits = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
        for tree in ("study", "teleop_core", "db", "examples")
        for path in sorted((ROOT / tree).rglob("*.py"))
        if path.relative_to(ROOT).as_posix() not in {own, *RENAMED_BY_HAND}
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if HAND_MADE.search(line)
    ]
    assert hits == [], "use teleop_core.files:\n" + "\n".join(hits)
    for module in RENAMED_BY_HAND:
        text = (ROOT / module).read_text(encoding="utf-8")
        assert HAND_MADE.search(text), f"{module} no longer renames by hand: drop it"
