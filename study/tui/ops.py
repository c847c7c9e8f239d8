"""The overview screen's end-of-day keys: export the data, check and back up the database.

`e` writes what `study export` writes (trials, NASA-TLX and the codebook, CSV) to a new
folder under the app's exports folder; `b` runs `study db backup`'s check and copy
(`db.maintenance`). Each asks for the folder first (the default filled in), runs in a
worker, and ends in one line on the overview and in a notification; a failure is the
database-error line of `study.tui.db_errors`, and nothing half-written is left.
"""

from __future__ import annotations

import shutil
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, cast

from textual import work
from textual.widgets import Static

from study.tui.db_errors import SafeWorkers
from teleop_core.files import replace_durably

if TYPE_CHECKING:
    from textual.widget import Widget

    from study.tui.services import StudyServices

    _Pane = Widget
else:
    _Pane = object  # the pane it joins is the widget

__all__ = ["OpsMixin", "export_folder"]


class _Folders(Protocol):
    """The folders of the app's settings (`TuiSettings`) the keys write in."""

    @property
    def exports_dir(self) -> Path: ...

    @property
    def backups_dir(self) -> Path: ...


class _OpsApp(Protocol):
    """What the keys ask of the app (`StudyApp`, which imports this module's pane)."""

    @property
    def settings(self) -> _Folders: ...

    @property
    def services(self) -> StudyServices: ...


def export_folder(base: Path, now: datetime | None = None) -> Path:
    """A new folder under `base` named by the time (UTC) of the export."""
    stamp = (now or datetime.now(UTC)).astimezone(UTC).strftime("%Y%m%dT%H%M%SZ")
    return base / stamp


class OpsMixin(SafeWorkers, _Pane):
    """Export and end-of-day backup for a pane with an `#ops-status` Static."""

    last_ops_line = ""

    @property
    def _study(self) -> _OpsApp:
        """The app the pane is in: its settings and services."""
        return cast("_OpsApp", self.app)

    def _ask_folder(self, question: str, default: Path, enter: str, then: Any) -> None:
        # here, not at the top: importing study.tui.confirm imports this module
        from study.tui.confirm import ReasonScreen

        def answered(text: str | None) -> None:
            if text:
                then(Path(text).expanduser())

        screen = ReasonScreen(question, "folder", str(default), enter=enter, limit=None)
        self.app.push_screen(screen, answered)

    def action_export_data(self) -> None:
        """e: trials, NASA-TLX and the codebook, as `study export --out FOLDER` writes them."""
        settings = self._study.settings
        self._ask_folder(
            "Export the trials, NASA-TLX and codebook (CSV) to the folder:",
            export_folder(settings.exports_dir),
            "export to this folder",
            self._start_export,
        )

    def _start_export(self, folder: Path) -> None:
        self._ops_status(f"exporting to {folder}...")
        self._export(folder)

    @work(thread=True, exclusive=True, group="export", exit_on_error=False)
    def _export(self, folder: Path) -> None:
        # lazy: study.protocol.export (with pandas, pyarrow, numpy) costs 0.4 s at start-up
        from study.protocol.export import export_data

        created = not folder.exists()
        try:
            written = export_data(self._study.services.engine, folder, "csv")
        except BaseException:
            if created and folder.is_dir():  # nothing half-written: the folder made goes
                shutil.rmtree(folder, ignore_errors=True)
            raise
        names = ", ".join(p.name for p in written)
        line = f"exported {len(written)} files to {folder}: {names}"
        self.app.call_from_thread(self._ops_done, line, True)

    def action_backup(self) -> None:
        """b: the integrity check, then a checked copy (`study db backup`)."""
        settings = self._study.settings
        self._ask_folder(
            "End of day: check the database, then copy it (one SQLite file) to the folder:",
            settings.backups_dir,
            "check, then back up to this folder",
            self._start_backup,
        )

    def _start_backup(self, folder: Path) -> None:
        self._ops_status("checking the database...")
        self._backup(folder)

    @work(thread=True, exclusive=True, group="backup", exit_on_error=False)
    def _backup(self, folder: Path) -> None:
        # lazy: db.maintenance costs 8 ms at start-up
        from db.maintenance import backup_database

        def notice(line: str) -> None:
            self.app.call_from_thread(self._ops_status, f"{line}...")

        engine = self._study.services.engine
        result = backup_database(engine, folder, notice=notice, replace_file=replace_durably)
        ok = result.source.ok and result.copy.ok
        self.app.call_from_thread(self._ops_done, result.line(), ok)

    def _ops_done(self, line: str, ok: bool) -> None:
        self._ops_status(line)
        self.app.notify(line, severity="information" if ok else "error", timeout=15)

    def worker_failed(self, group: str, line: str) -> None:
        what = {"export": "not exported", "backup": "no backup made"}.get(group, "failed")
        line = f"{what}: {line}"
        self._ops_status(line)
        super().worker_failed(group, line)

    def _ops_status(self, text: str) -> None:

        self.last_ops_line = text
        self.query_one("#ops-status", Static).update(text)
