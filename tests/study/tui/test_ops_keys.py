"""The overview's end-of-day keys: e exports what `study export` writes, b checks the
database and backs it up; each ends in one line."""

from __future__ import annotations

import csv
import filecmp
from pathlib import Path

from study.cli import main
from study.tui.confirm import ReasonScreen
from tests.study.tui.conftest import loaded, store_trials, wait_for


async def _answer(pilot, folder: Path) -> None:
    """The folder dialog: the default replaced by `folder`, then Enter."""
    from textual.widgets import Input

    await wait_for(pilot, lambda: isinstance(pilot.app.screen, ReasonScreen), 10)
    pilot.app.screen.query_one("#reason-text", Input).value = str(folder)
    await pilot.press("enter")


async def test_e_exports_what_study_export_writes(make_test_app, study_engine, tmp_path) -> None:
    store_trials(study_engine)
    app = make_test_app(exports_dir=tmp_path / "exports")
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        pane = app.query_one("#overview-pane")
        await pilot.press("f1", "e")
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        # the default: a new folder under the exports folder, named by the time
        default = app.screen.query_one("#reason-text").value
        assert Path(default).parent == tmp_path / "exports"
        await pilot.press("escape")
        await pilot.press("e")
        await _answer(pilot, tmp_path / "from-app")
        await wait_for(pilot, lambda: pane.last_ops_line.startswith("exported"), 60)
        line = pane.last_ops_line
    assert "\n" not in line
    assert line.startswith(f"exported 3 files to {tmp_path / 'from-app'}")
    # the same files as the command writes, byte for byte (the codebook too)
    db = str(study_engine.url.database)
    assert main(["export", "--db", db, "--out", str(tmp_path / "from-cli")]) == 0
    app_files = sorted(p.name for p in (tmp_path / "from-app").iterdir())
    assert app_files == sorted(p.name for p in (tmp_path / "from-cli").iterdir())
    _, mismatch, errors = filecmp.cmpfiles(
        tmp_path / "from-app", tmp_path / "from-cli", app_files, shallow=False
    )
    assert (mismatch, errors) == ([], [])
    with (tmp_path / "from-app" / "trials.csv").open() as f:
        assert len(list(csv.DictReader(f))) == 12  # 6 people x 2 conditions (store_trials)


async def test_b_checks_and_backs_up_in_one_line(make_test_app, study_engine, tmp_path) -> None:
    app = make_test_app(backups_dir=tmp_path / "backups")
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        pane = app.query_one("#overview-pane")
        await pilot.press("b")  # the overview has the focus at start
        await wait_for(pilot, lambda: isinstance(app.screen, ReasonScreen), 10)
        assert app.screen.query_one("#reason-text").value == str(tmp_path / "backups")
        await pilot.press("enter")
        await wait_for(pilot, lambda: pane.last_ops_line.endswith("checked ok"), 60)
        line = pane.last_ops_line
    [copy] = list((tmp_path / "backups").iterdir())
    assert "\n" not in line
    assert "integrity ok" in line
    assert f"copy {copy} (" in line
    # the copy is a study database the command checks as sound
    assert main(["db", "check", "--db", str(copy)]) == 0
