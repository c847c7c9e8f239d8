"""The layer contracts inside `study` (pyproject.toml) catch what they are for: in a copy
of the tree with violations planted, each contract breaks and names its module."""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

from tests.test_layering import ROOT, _lint_imports

PLANTED = {  # module -> (statement, contract it breaks)
    "study.protocol._up_to_the_screens": ("from study.tui import make_app", "study's layers"),
    "study.bench._up_to_the_commands": ("from study.commands import base", "study's layers"),
    "study.analysis._a_cli_import": ("import click", "below the command line and the screens"),
}


def test_planted_violations_break_the_study_contracts(tmp_path: Path) -> None:
    for name in ("teleop_core", "db", "study"):
        shutil.copytree(
            ROOT / name, tmp_path / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc")
        )
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    for module, (statement, _) in PLANTED.items():
        tmp_path.joinpath(*module.split(".")).with_suffix(".py").write_text(f"{statement}\n")

    result = _lint_imports(tmp_path)

    assert result.returncode != 0
    report = " ".join(result.stdout.split())  # contract names wrap at 80 columns
    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    names = [c["name"] for c in contracts["contracts"]]
    for module, (_, prefix) in PLANTED.items():
        (name,) = [n for n in names if n.startswith(prefix)]
        assert f"{name} BROKEN" in report
        assert f"{module} -> " in report
