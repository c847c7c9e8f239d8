"""`study run`: a participant's session, headless."""

from __future__ import annotations

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

from db.migrate import open_database
from study.commands.base import StudyCommand, db_option
from study.errors import StudyInputError
from study.protocol.default_estimator import load_estimator
from study.protocol.session import run_session


@click.command("run", cls=StudyCommand)
@click.option("--participant", "code", required=True, help="Participant code, e.g. P003.")
@click.option(
    "--driver",
    type=click.Choice(["simulated", "keyboard", "hardware"]),
    default="simulated",
    show_default=True,
)
@click.option("--port", help="Serial port of the dial's ESP32 (hardware driver).")
@click.option(
    "--pace",
    type=click.FloatRange(min=0, min_open=True),
    help="Run a simulated session at this many times real time [default: as fast as it goes].",
)
@db_option
def run(code: str, driver: str, port: str | None, pace: float | None, db_url: str | None) -> None:
    """Run the participant's remaining scheduled trials and store every sample."""
    if driver == "keyboard":
        raise StudyInputError("the keyboard driver needs the terminal app; expected `study tui`")
    make_driver = None
    if driver == "hardware":
        if not port:
            raise StudyInputError("--driver hardware needs --port, e.g. --port /dev/ttyUSB0")
        from teleop_core.loop.hardware import HardwareDriver

        make_driver = lambda: HardwareDriver.open(port)  # noqa: E731
    estimator = load_estimator()
    engine = open_database(db_url, create=False)
    try:
        with Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            console=Console(stderr=True),
            transient=True,
        ) as progress:
            bar = progress.add_task(f"session {code}", total=None)

            def report(item, k, n) -> None:
                kind = "practice" if item.practice else "trial"
                progress.update(
                    bar,
                    total=n,
                    completed=k,
                    description=f"{code} {item.block.task}/{item.block.condition} "
                    f"{kind} {item.trial_index + 1}",
                )

            done = run_session(engine, code, driver, estimator, make_driver, pace, report)
    finally:
        engine.dispose()
    click.echo(f"{code}: {len(done)} trials completed and stored")
