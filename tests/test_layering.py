"""The one direction of dependency (DESIGN.md, Architecture) is a contract CI checks.

import-linter reads the contracts from pyproject.toml. The tests run it on the real
tree, show that it fails on a copy of the tree with a violation planted, and import
every `teleop_core` module in a fresh interpreter to see nothing forbidden load.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT_IMPORTS = Path(sysconfig.get_path("scripts")) / "lint-imports"


def _lint_imports(cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    return subprocess.run(
        [str(LINT_IMPORTS), "--no-cache"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_the_tree_keeps_the_layering_contracts() -> None:
    result = _lint_imports(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 broken" in result.stdout


@pytest.mark.parametrize(
    ("package", "statement", "contract"),
    [
        ("teleop_core", "import sqlalchemy", "teleop_core is plain numerics"),
        ("teleop_core", "from textual.app import App", "teleop_core is plain numerics"),
        ("teleop_core", "import db.engine", "teleop_core is plain numerics"),
        ("teleop_core", "from study import cli", "teleop_core is plain numerics"),
        ("db", "import study.errors", "db knows nothing of the study application"),
    ],
)
def test_a_planted_violation_breaks_the_contract(
    tmp_path: Path, package: str, statement: str, contract: str
) -> None:
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in ("teleop_core", "db", "study"):
        shutil.copytree(ROOT / name, tmp_path / name, ignore=ignore)
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    (tmp_path / package / "_planted_violation.py").write_text(f"{statement}\n")

    result = _lint_imports(tmp_path)

    assert result.returncode != 0
    assert f"{contract}" in result.stdout
    assert f"{package}._planted_violation" in result.stdout
    assert "BROKEN" in result.stdout


_LIST_LOADED = """
import importlib, pkgutil, sys
import teleop_core
for info in pkgutil.walk_packages(teleop_core.__path__, "teleop_core."):
    importlib.import_module(info.name)
forbidden = ("db", "study", "sqlalchemy", "alembic", "textual")
print(sorted(m for m in sys.modules if m.split(".")[0] in forbidden))
"""


def test_importing_all_of_teleop_core_loads_no_database_app_or_ui() -> None:
    result = subprocess.run(
        [sys.executable, "-c", _LIST_LOADED], capture_output=True, text=True, cwd=ROOT
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"
