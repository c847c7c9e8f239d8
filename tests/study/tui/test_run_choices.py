"""The run screen's driver and pace are kept across restarts, per database, in the
user's settings file (`study.tui.preferences`); `--pace` still wins."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from db.migrate import open_database
from study.cli import main
from study.tui import StudyServices, TuiSettings, make_app
from study.tui.preferences import (
    RunChoices,
    database_key,
    load_run_choices,
    preferences_path,
    save_run_choices,
)
from tests.study.tui.conftest import run_screen


def test_choices_are_kept_per_database(tmp_path: Path, study_engine, monkeypatch) -> None:
    prefs = tmp_path / "config" / "tui.json"
    other = open_database(str(tmp_path / "other.db"), create=True)
    try:
        assert load_run_choices(study_engine, prefs) is None  # no file yet
        save_run_choices(study_engine, RunChoices("keyboard", 4.0), prefs)
        save_run_choices(other, RunChoices("simulated", None), prefs)
        assert load_run_choices(study_engine, prefs) == RunChoices("keyboard", 4.0)
        assert load_run_choices(other, prefs) == RunChoices("simulated", None)
        # the file names each database by its absolute path
        stored = json.loads(prefs.read_text())["databases"]
        assert stored[f"sqlite:///{tmp_path / 'study.db'}"] == {"driver": "keyboard", "pace": 4.0}
        # the same file named relative to another working folder is the same database
        monkeypatch.chdir(tmp_path)
        relative = open_database("study.db", create=False)
        assert database_key(relative) == database_key(study_engine)
        relative.dispose()
    finally:
        other.dispose()
    prefs.write_text("{ not json")  # damaged: nothing remembered, no error
    assert load_run_choices(study_engine, prefs) is None


def test_the_settings_file_follows_xdg_config_home(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert preferences_path() == tmp_path / "xdg" / "haptic-study" / "tui.json"


async def test_d_and_p_are_there_after_a_restart(study_engine, tmp_path: Path) -> None:
    prefs = tmp_path / "tui.json"

    def app_as_started():
        remembered = load_run_choices(study_engine, prefs) or RunChoices()
        settings = TuiSettings(
            simulated_pace=remembered.pace,
            driver=remembered.driver,
            preferences_file=prefs,
            prepare_simulation=False,
            figures_dir=tmp_path / "figures",
        )
        return make_app(StudyServices(study_engine, lambda: None), settings)

    app = app_as_started()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        await pilot.press("p", "d")  # 1x -> 4x, then the keyboard drives
        assert (pane.driver_kind, pane.pace) == ("keyboard", 4.0)
    app = app_as_started()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        assert (pane.driver_kind, pane.pace) == ("keyboard", 4.0)
        assert "driver: keyboard" in str(app.query_one("#mode").render())
        await pilot.press("d")  # simulated again: its pace is the one kept
        assert "pace: 4x" in str(app.query_one("#mode").render())


@pytest.mark.parametrize(
    ("args", "expected"), [([], (4.0, "keyboard")), (["--pace", "2"], (2.0, "keyboard"))]
)
def test_study_tui_starts_with_the_kept_choices_unless_pace_is_given(
    study_engine, tmp_path: Path, monkeypatch, args, expected
) -> None:
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    save_run_choices(study_engine, RunChoices("keyboard", 4.0))
    started: list[TuiSettings] = []

    class NotRun:
        return_code = 0

        def run(self) -> None:
            pass

    def fake_make_app(services, settings):
        started.append(settings)
        return NotRun()

    monkeypatch.setattr("study.tui.make_app", fake_make_app)
    db = str(study_engine.url.database)
    assert main(["tui", "--db", db, *args]) == 0
    [settings] = started
    assert (settings.simulated_pace, settings.driver) == expected
    assert settings.preferences_file == tmp_path / "xdg" / "haptic-study" / "tui.json"
