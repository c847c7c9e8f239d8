"""The run screen's driver and pace, remembered per database across restarts.

They are kept in a settings file of the user running the app, not in the study
database: the driver is a property of the lab machine (a keyboard, the device attached),
the pace of the experimenter's habit, and a study database shared by several machines
(PostgreSQL) or copied read-only must not change because one of them pressed `d`. The
file is `$XDG_CONFIG_HOME/haptic-study/tui.json` (`~/.config/...` without it), one entry
per database (its URL, password hidden; an SQLite path made absolute), written whole
to a temporary file and renamed, so an interrupted write leaves the previous one.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import Engine

from teleop_core.files import write_atomically

__all__ = ["RunChoices", "database_key", "load_run_choices", "preferences_path", "save_run_choices"]

DRIVERS = ("simulated", "keyboard")


@dataclass(frozen=True)
class RunChoices:
    """What the run screen starts with."""

    driver: str = "simulated"
    pace: float | None = 1.0
    """Times real time for a simulated participant; None: as fast as it goes."""


def preferences_path() -> Path:
    """`$XDG_CONFIG_HOME/haptic-study/tui.json`, else under `~/.config`."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "haptic-study" / "tui.json"


def database_key(engine: Engine) -> str:
    """The database as the file names it: its URL without the password; for SQLite the
    absolute path, so `--db study.db` from two folders are two databases."""
    url = engine.url
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        url = url.set(database=str(Path(url.database).resolve()), query={})
    return url.render_as_string(hide_password=True)


def _read(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):  # none yet, unreadable or damaged: nothing remembered
        return {}
    return data if isinstance(data, dict) else {}


def load_run_choices(engine: Engine, path: Path | None = None) -> RunChoices | None:
    """The choices remembered for the database, or None (none, or not readable)."""
    entry = _read(path or preferences_path()).get("databases", {}).get(database_key(engine))
    if not isinstance(entry, dict):
        return None
    driver = entry.get("driver")
    pace = entry.get("pace", 1.0)
    if driver not in DRIVERS:
        return None
    if pace is not None and not (isinstance(pace, int | float) and pace > 0):
        return None
    return RunChoices(driver, None if pace is None else float(pace))


def save_run_choices(engine: Engine, choices: RunChoices, path: Path | None = None) -> None:
    """Remember `choices` for the database (raises OSError if the file cannot be written)."""
    path = path or preferences_path()
    data = _read(path)
    databases = data.get("databases")
    if not isinstance(databases, dict):
        databases = data["databases"] = {}
    databases[database_key(engine)] = {"driver": choices.driver, "pace": choices.pace}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, json.dumps(data, indent=2, sort_keys=True))
