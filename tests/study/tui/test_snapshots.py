"""Snapshots of the main screens at 80 x 24 (and the overview in the light theme).

Update with `pytest tests/study/tui/test_snapshots.py --snapshot-update` after a
deliberate change of the screens, and look at the report of what changed.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from study.tui.tlx_pane import TlxPane
from tests.study.tui.conftest import loaded

SIZE = (80, 24)


def _shot(snap_compare, app, key: str | None = None, then=None) -> bool:
    async def before(pilot) -> None:
        await loaded(pilot)
        if key:
            await pilot.press(key)
        if then is not None:
            await then(pilot)
        await pilot.pause(0.2)

    return snap_compare(app, terminal_size=SIZE, run_before=before)


@pytest.mark.parametrize(
    ("key", "theme"),
    [
        (None, "textual-dark"),
        (None, "textual-light"),
        ("f2", "textual-dark"),
        ("f3", "textual-dark"),
        ("f5", "textual-dark"),
        ("f6", "textual-dark"),
    ],
    ids=["overview", "overview-light", "participants", "run", "analysis", "calibration"],
)
def test_screen(snap_compare, make_test_app, key, theme) -> None:
    # a relative figures folder: the tests' temporary one changes from run to run
    assert _shot(snap_compare, make_test_app(theme=theme, figures_dir=Path("figures")), key)


def test_tlx_form(snap_compare, make_test_app) -> None:
    async def open_block(pilot) -> None:
        pane = pilot.app.query_one(TlxPane)
        pane.open_block("P001", "lcca", "VO")
        while pane.status == "":
            await pilot.pause(0.05)

    assert _shot(snap_compare, make_test_app(), "f4", open_block)
