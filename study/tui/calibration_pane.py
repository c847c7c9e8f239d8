"""The calibration screen: run the calibration loop on a recording and show its report.

The loop itself (`teleop_core.calibration`) is passed into `make_app` as
`StudyServices.calibrate` (recording, model, progress) -> report, with the keys of
`study calibrate`'s REPORT.json (`rmse_before`, `rmse_after`, `effects_added`,
`candidates_rejected`); `study tui` passes `services.calibrate_recording`. Without one
the screen says it has no calibration loop. The loop runs in a worker; its progress
lines come back as messages.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import DataTable, Input, Label, Select, Static

from study.protocol.calibrations import list_calibrations, store_calibration
from study.tui.db_errors import SafeWorkers
from study.tui.services import StudyServices
from teleop_core.progress import describe

__all__ = ["MODELS", "CalibrationPane"]

MODELS = ("follower", "master", "notes-translation", "notes-rotation")
"""`study calibrate --model` choices."""


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, dict):
        return ", ".join(f"{k} {_fmt(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return str(value)


class CalibrationPane(SafeWorkers, Vertical):
    """Pick a recording and a model, run the loop, read the report."""

    DEFAULT_CSS = """
    CalibrationPane { height: 1fr; }
    CalibrationPane .row { height: 1; }
    CalibrationPane #recording { width: 1fr; }
    CalibrationPane #model { width: 22; }
    CalibrationPane #calib-summary { height: auto; }
    CalibrationPane #effects { height: 1fr; min-height: 4; }
    CalibrationPane #stored { height: 7; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [Binding("ctrl+r", "calibrate", "Calibrate")]

    @dataclass
    class Progress(Message):
        text: str

    @dataclass
    class Done(Message):
        report: dict[str, Any]

    @dataclass
    class Stored(Message):
        calibration_id: int
        path: Path
        stored: list[dict[str, Any]]

    @dataclass
    class Listed(Message):
        stored: list[dict[str, Any]]

    def __init__(
        self, services: StudyServices, out_dir: Path = Path("calibrations"), **kwargs: object
    ) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self.services = services
        self.out_dir = out_dir
        self.report: dict[str, Any] | None = None
        self.stored_path: Path | None = None

    def compose(self) -> ComposeResult:
        with Horizontal(classes="row"):
            yield Label("Recording ")
            yield Input(
                placeholder="path to RECORDING.csv",
                id="recording",
                compact=True,
                select_on_focus=False,
            )
            yield Select[str](
                [(m, m) for m in MODELS],
                id="model",
                value="follower",
                compact=True,
                allow_blank=False,
            )
        waiting = self.services.calibrate is None
        yield Static(
            "no calibration loop was given to this app"
            if waiting
            else "ctrl+r: run the calibration loop on the recording",
            id="calib-summary",
        )
        table: DataTable[str] = DataTable(id="effects", zebra_stripes=True, cursor_type="row")
        table.add_columns("step", "effect added", "held-out RMSE (N)", "parameters")
        yield table
        yield Label("Stored calibrations (newest first)")
        stored: DataTable[str] = DataTable(id="stored", zebra_stripes=True, cursor_type="row")
        stored.add_columns(
            "id", "when (UTC)", "model", "recording", "RMSE before -> after", "verdict"
        )
        yield stored

    def on_mount(self) -> None:
        self._list()

    @work(thread=True, exclusive=True, group="calibrations", exit_on_error=False)
    def _list(self) -> None:

        self.post_message(self.Listed(list_calibrations(self.services.engine)))

    @on(Listed)
    def _listed(self, event: Listed) -> None:
        self._show_stored(event.stored)

    def _show_stored(self, stored: list[dict[str, Any]]) -> None:
        table = self.query_one("#stored", DataTable)
        table.clear()
        for r in stored:
            rmse = f"{_fmt(r['rmse_before'])} -> {_fmt(r['rmse_after'])}"
            table.add_row(
                str(r["id"]),
                f"{r['at']:%Y-%m-%d %H:%M}",
                r["model"],
                r["recording"],
                rmse,
                r["verdict"] or "",
            )

    def action_calibrate(self) -> None:
        if self.services.calibrate is None:
            self._summary("no calibration loop was given to this app: nothing to run")
            return
        typed = self.query_one("#recording", Input).value.strip()
        if not typed:
            self._summary("refused: type the path of a recording first (a CSV or .mat file)")
            return
        path = Path(typed)
        if not path.is_file():
            self._summary(f"refused: recording {str(path)!r} is not a file")
            return
        model = str(self.query_one("#model", Select).value)
        self._summary(f"calibrating {path.name} ({model})...")
        self._run(path, model)

    def _told(self, step: str, done: int = 0, total: int = 0) -> None:
        """The loop's `teleop_core.progress.Progress`: a line under the form."""
        self.post_message(self.Progress(f"calibrating: {describe(step, done, total)}"))

    @work(thread=True, exclusive=True, group="calibrate", exit_on_error=False)
    def _run(self, path: Path, model: str) -> None:
        calibrate = self.services.calibrate
        if calibrate is None:  # pragma: no cover - checked before the worker starts
            return
        try:
            report = calibrate(path, model, self._told)
        except ValueError as exc:
            self.app.call_from_thread(self._summary, f"refused: {exc}")
            return
        self.post_message(self.Done(report))

        calibration_id, stored_at = store_calibration(
            self.services.engine, model, path, report, self.out_dir
        )
        self.post_message(
            self.Stored(calibration_id, stored_at, list_calibrations(self.services.engine))
        )

    @on(Stored)
    def _stored(self, event: Stored) -> None:
        self.stored_path = event.path
        self._show_stored(event.stored)
        self.app.notify(f"calibration {event.calibration_id} stored; report in {event.path}")

    def worker_failed(self, group: str, line: str) -> None:
        if group == "calibrate":
            line = f"the calibration failed or was not stored: {line}"
        super().worker_failed(group, line)

    @on(Progress)
    def _progress(self, event: Progress) -> None:
        self._summary(event.text)

    @on(Done)
    def _done(self, event: Done) -> None:
        self.report = report = event.report
        before, after = report.get("rmse_before"), report.get("rmse_after")
        text = Text()
        if isinstance(before, float) and isinstance(after, float):
            cut = 100 * (1 - after / before) if before else 0.0
            text.append(f"held-out RMSE {before:.4f} N -> {after:.4f} N ({cut:.0f} % lower)\n")
        rejected = report.get("candidates_rejected") or []
        names = [r.get("family", str(r)) if isinstance(r, dict) else str(r) for r in rejected]
        text.append(f"rejected: {', '.join(names) or 'none'}")
        self._summary(text)
        table = self.query_one("#effects", DataTable)
        table.clear()
        for k, e in enumerate(report.get("effects_added") or [], 1):
            # one parameter per line: a row grows in height, not past the screen's width
            params = e.get("params")
            cell = (
                "\n".join(f"{name} {_fmt(v)}" for name, v in params.items())
                if isinstance(params, dict)
                else _fmt(params)
            )
            table.add_row(
                str(k), str(e.get("family")), _fmt(e.get("rmse_after_step")), cell, height=None
            )

    def _summary(self, text: str | Text) -> None:
        self.query_one("#calib-summary", Static).update(text)
