"""The fast lane's lists name real tests: a module in `SLOW_MODULES` or a node id prefix
in `SLOW_TESTS` that no longer matches anything (a file renamed, a test renamed) would
silently put a heavy test back in the fast lane, or leave nothing out at all."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.conftest import FAST_LANE, SLOW_MODULES, SLOW_TESTS, pytest_ignore_collect

ROOT = Path(__file__).resolve().parents[1]


def _test_functions(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [
        node.name
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.name.startswith("test_")
    ]


@pytest.mark.parametrize("module", sorted(SLOW_MODULES))
def test_every_slow_module_is_a_test_module_with_tests(module: str) -> None:
    path = ROOT / module
    assert path.is_file(), f"{module} is in SLOW_MODULES but does not exist"
    assert _test_functions(path), f"{module} holds no test function"


@pytest.mark.parametrize("prefix", SLOW_TESTS)
def test_every_slow_test_prefix_names_a_test_of_a_fast_module(prefix: str) -> None:
    module, _, name = prefix.partition("::")
    path = ROOT / module
    assert path.is_file(), f"{prefix}: {module} does not exist"
    assert module not in SLOW_MODULES, f"{prefix}: the whole module is slow already"
    matching = [f for f in _test_functions(path) if f.startswith(name)]
    assert matching, f"{prefix}: no test in {module} starts with {name!r}"


class _Config:
    """The one option `pytest_ignore_collect` reads."""

    def __init__(self, markexpr: str) -> None:
        self.markexpr = markexpr

    def getoption(self, name: str) -> str:
        assert name == "markexpr"
        return self.markexpr


@pytest.mark.parametrize(
    ("markexpr", "module", "ignored"),
    [
        (FAST_LANE, "tests/teleop_core/test_gru.py", True),
        ("not   slow", "tests/teleop_core/test_gru.py", True),
        (FAST_LANE, "tests/test_lanes.py", None),
        ("", "tests/teleop_core/test_gru.py", None),
        ("slow", "tests/teleop_core/test_gru.py", None),
        ("not slow and not postgres", "tests/teleop_core/test_gru.py", None),
    ],
)
def test_only_the_fast_lane_skips_importing_the_slow_modules(
    markexpr: str, module: str, ignored: bool | None
) -> None:
    config = _Config(markexpr)
    assert pytest_ignore_collect(ROOT / module, config) is ignored
