"""No module of the `study` package grows past 400 lines (issue 20): a module that long
has more than one job, and the next change to it is harder to review than a split.

"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 400
def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_no_study_module_is_over_the_limit() -> None:
    too_long = {
        rel: n
        for path in sorted((ROOT / "study").rglob("*.py"))
        if (n := _lines(path)) > MAX_LINES
        and (rel := path.relative_to(ROOT).as_posix())
    }
    assert not too_long, (
        f"modules over {MAX_LINES} lines (split them along a real seam): "
        + ", ".join(f"{rel} ({n})" for rel, n in too_long.items())
    )


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
