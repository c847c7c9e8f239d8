"""Headless timings of the terminal app, for `study bench tui` and `study bench startup`.

They drive the app under a Textual pilot (80 x 24) and read the moments it records
(`StudyApp.started_at`, `overview_shown_s`, `ready`), so they live beside the app; the
benches call them (the run-screen probe in a fresh process: `python -c`, see
`study.bench.startup`) and stay below the screens.
"""

from __future__ import annotations

import asyncio
import json
import resource
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from db.migrate import open_database
from study.errors import StudyInputError
from study.tui.app import TuiSettings, make_app
from study.tui.services import StudyServices, load_shipped_estimator

if TYPE_CHECKING:
    from teleop_core.estimation.model import ForceEstimator


def _no_estimator() -> ForceEstimator:
    """The estimator of a timing that runs no trial: asked for, it is a mistake."""
    raise RuntimeError("this timing of the terminal app runs no trial; it has no estimator")


POLL_S = 0.05
"""How often the run-screen probe looks, s: its resolution. Each look waits for the app
to settle; looking every 5 ms doubled the time measured (the app's main thread then
holds the GIL the preparing worker needs)."""


def overview_seconds(db_url: str) -> float:
    """Seconds from `make_app` to the overview with data, headless in this process."""
    engine = open_database(db_url, create=False)

    async def run() -> float:
        app = make_app(StudyServices(engine, _no_estimator), TuiSettings())
        async with app.run_test(size=(80, 24)) as pilot:
            while not app.ready:  # the overview shows first, the other screens follow
                await pilot.pause(0.01)
            return app.overview_shown_s  # type: ignore[return-value]

    try:
        return asyncio.run(run())
    finally:
        engine.dispose()


def _give_up_after(
    started_at: float, limit_s: float = 120.0, what: str = "the run screen was not ready"
) -> None:
    if time.monotonic() - started_at > limit_s:
        raise StudyInputError(f"{what} {limit_s:.0f} s after the start")


def print_run_screen_seconds(db_url: str) -> None:
    """In a fresh process: print JSON with the seconds from the overview showing to the run
    screen prepared (headless, 80 x 24)."""
    engine = open_database(db_url, create=False)

    async def run() -> float:
        app = make_app(StudyServices(engine, load_shipped_estimator), TuiSettings())
        async with app.run_test(size=(80, 24)) as pilot:
            while not app.ready:  # the run screen can be opened once mounted
                _give_up_after(app.started_at)
                await pilot.pause(POLL_S)
            overview_at = app.started_at + app.overview_shown_s  # type: ignore[operator]
            app.action_tab("run")
            pane: Any = app.query_one("#run-pane")
            while pane.simulation.estimator is None or pane.status != "idle":
                _give_up_after(app.started_at)  # e.g. the estimator failed to load
                await pilot.pause(POLL_S)
            return time.monotonic() - overview_at

    try:
        seconds = asyncio.run(run())
    finally:
        engine.dispose()
    print(json.dumps({"seconds": seconds}))


def print_analysis_figures_peak(db_url: str, folder: str) -> None:
    """In a fresh process: the analysis screen's two jobs on the study, headless (120 x
    40): the overview, then F5, `r` (the analysis) and ctrl+e (the paper's figures, as
    PNG, into `folder`); prints JSON with the seconds, the figure files and the peak
    resident memory of this process in MB (`study bench export`)."""

    engine = open_database(db_url, create=False)
    settings = TuiSettings(figures_dir=Path(folder), figure_formats=("png",))

    async def run() -> list[str]:
        app = make_app(StudyServices(engine, _no_estimator), settings)
        async with app.run_test(size=(120, 40)) as pilot:
            while not app.ready:
                _give_up_after(app.started_at)
                await pilot.pause(POLL_S)
            app.action_tab("analysis")
            pane: Any = app.query_one("AnalysisPane")
            pane.action_analyze()
            while pane.result is None:
                _give_up_after(app.started_at, 600.0, "the analysis had no result")
                await pilot.pause(POLL_S)
            pane.action_export()
            while not pane.exported:
                _give_up_after(app.started_at, 600.0, "no figure was written")
                await pilot.pause(POLL_S)
            return [str(p) for p in pane.exported]

    start = time.monotonic()
    try:
        files = asyncio.run(run())
    finally:
        engine.dispose()
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"seconds": time.monotonic() - start, "files": files, "peak_mb": peak_mb}))
