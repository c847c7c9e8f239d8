"""The `study` package's structure: no import cycle. (A module's length is not held to a
line budget: a module has one job, and ruff and the import contracts keep the rest.)"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_study_has_no_import_cycle() -> None:
    """No module of `study` imports itself back through others (grimp sees what
    import-linter sees, lazy and type-checking imports included)."""
    import graphlib

    import grimp

    graph = grimp.build_graph("study")
    edges = {m: graph.find_modules_directly_imported_by(m) for m in graph.modules}
    try:
        tuple(graphlib.TopologicalSorter(edges).static_order())
    except graphlib.CycleError as exc:
        raise AssertionError(f"import cycle: {' -> '.join(exc.args[1])}") from None
