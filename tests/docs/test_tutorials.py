"""Every tutorial of the documentation runs, as written, and leaves what it promises.

Each page under `docs/tutorials/` is a sequence of fenced blocks; the blocks marked
`bash` are what a reader types, and this test runs them in order, in one shell, in a
fresh folder that holds what a clone holds at its root (`tests/data`, `examples`,
`firmware`). Blocks marked
`console` are shown only: they need a device, a cluster or a server this test does not
have. A page names what it leaves with an `<!-- expects: PATH ... -->` comment, and the
test checks those files exist after its blocks ran.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TUTORIALS = ROOT / "docs" / "tutorials"
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```", re.MULTILINE | re.DOTALL)
EXPECTS = re.compile(r"<!--\s*expects:\s*(.*?)\s*-->", re.DOTALL)


def bash_blocks(markdown: str) -> list[str]:
    """The `bash` fenced blocks of a page, in order."""
    return [body for lang, body in FENCE.findall(markdown) if lang == "bash"]


def expected_paths(markdown: str) -> list[str]:
    """The paths a page says its commands leave."""
    return [p for match in EXPECTS.findall(markdown) for p in match.split()]


def test_blocks_are_found_in_order() -> None:
    page = "x\n```bash\necho one\n```\n```console\nnot run\n```\n```bash\necho two\n```\n"
    assert bash_blocks(page) == ["echo one\n", "echo two\n"]
    assert expected_paths("<!-- expects: a/b.json c.png -->") == ["a/b.json", "c.png"]


PAGES = sorted(TUTORIALS.glob("*.md"))


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_tutorial_runs_as_written(page: Path, tmp_path: Path) -> None:
    markdown = page.read_text(encoding="utf-8")
    blocks = bash_blocks(markdown)
    if not blocks:
        pytest.skip(f"{page.name} has no commands to run")
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "data").symlink_to(ROOT / "tests" / "data")
    shutil.copytree(ROOT / "examples", tmp_path / "examples")  # a lab's task to install
    (tmp_path / "firmware").symlink_to(ROOT / "firmware")  # the units' source, built in place
    script = "set -euo pipefail\n" + "\n".join(blocks)
    env = dict(os.environ)
    env.pop("STUDY_DB", None)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    result = subprocess.run(
        [shutil.which("bash") or "/bin/bash", "-c", script],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, (
        f"{page.name}: the commands stopped with status {result.returncode}\n"
        f"stdout (end):\n{result.stdout[-3000:]}\nstderr (end):\n{result.stderr[-3000:]}"
    )
    missing = [p for p in expected_paths(markdown) if not (tmp_path / p).exists()]
    assert not missing, f"{page.name} promises {missing}, which its commands did not write"
