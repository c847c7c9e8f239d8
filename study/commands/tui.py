"""`study tui`: the terminal app over a study database."""

from __future__ import annotations

from pathlib import Path

import click

from study.commands.base import StudyCommand, db_option, positive_option


@click.command("tui", cls=StudyCommand)
@click.option(
    "--figures-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("figures"),
    show_default=True,
    help="Default folder for the analysis screen's figure export.",
)
@positive_option(
    "--pace",
    None,
    "Times real time for a simulated participant (the screen's p key cycles it). "
    "Default: the pace last chosen with p on this database, else 1.",
)
@click.option("--light", is_flag=True, help="Start in the light theme (ctrl+t toggles).")
@click.option(
    "--lsl",
    is_flag=True,
    help="Publish the trials' markers and samples as Lab Streaming Layer streams (as "
    "`[lsl] publish = true` in the design does); needs LSLAPICFG (see `study lsl-config`).",
)
@db_option
def tui(figures_dir: Path, pace: float | None, light: bool, lsl: bool, db_url: str | None) -> None:
    """The terminal app: overview, participants, sessions, NASA-TLX, analysis, calibration.

    \b
    Example:
      study tui --db lab.db
    """
    # lazy: db.migrate (with sqlalchemy) costs 0.3 s at start-up
    from db.migrate import open_database

    # lazy: study.tui (with sqlalchemy, textual, rich) costs 0.5 s at start-up
    from study.tui import StudyServices, TuiSettings, make_app

    # lazy: study.tui.preferences (with sqlalchemy, textual, rich) costs 0.5 s at start-up
    from study.tui.preferences import RunChoices, load_run_choices, preferences_path

    # lazy: study.tui.services (with sqlalchemy, textual, rich) costs 0.5 s at start-up
    from study.tui.services import calibrate_recording, load_shipped_estimator

    if lsl:
        from study.lsl.config import load_pylsl

        load_pylsl()  # no LSLAPICFG: one line now, not on the run screen
    engine = open_database(db_url, create=False)
    services = StudyServices(
        engine, load_shipped_estimator, calibrate=calibrate_recording, lsl_publish=lsl
    )
    try:
        # the driver and pace of the last start on this database (d, p), unless --pace
        remembered = load_run_choices(engine) or RunChoices()
        settings = TuiSettings(
            simulated_pace=remembered.pace if pace is None else pace,
            driver=remembered.driver,
            preferences_file=preferences_path(),
            figures_dir=figures_dir,
            theme="textual-light" if light else "textual-dark",
        )
        app = make_app(services, settings)
        app.run()
        if app.return_code:  # the app ended on an error (shown above): not a clean exit
            raise SystemExit(app.return_code)
    finally:
        services.close_lsl()
        engine.dispose()
