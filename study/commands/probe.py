"""`study probe run|list`: the design's probes for one participant, and what is stored."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import click

from study.commands.base import StudyGroup, db_option, opened_database, progress_bar
from study.errors import StudyInputError
from study.probes import get_probe, probes

if TYPE_CHECKING:
    from rich.progress import TaskID
    from sqlalchemy import Engine

    from study.probes.runner import Responder
    from study.protocol.observer import SessionObserver

DRIVERS = ("simulated", "keyboard", "hardware")


@click.group("probe", cls=StudyGroup)
def probe() -> None:
    """Probes: short measurements before a task (force threshold, reaction time, ...).

    \b
    Example:
      study probe run --participant P001
    """


@probe.command("run")
@click.option("--participant", "code", required=True, help="The participant's code.")
@click.option(
    "--probe",
    "only",
    multiple=True,
    help="Only this probe (repeatable) [default: every probe of the design].",
)
@click.option(
    "--driver",
    type=click.Choice(DRIVERS),
    default="simulated",
    show_default=True,
    help="Who answers: the participant's simulated person, the keyboard, or the "
    "dial unit on --port.",
)
@click.option("--port", default=None, help="The dial unit's serial port (--driver hardware).")
@click.option(
    "--lsl",
    is_flag=True,
    help="Publish a Lab Streaming Layer marker for each probe trial (as `[lsl] publish = "
    "true` in the design does); needs LSLAPICFG (see `study lsl-config`).",
)
@db_option
def run(
    code: str,
    only: tuple[str, ...],
    driver: str,
    port: str | None,
    lsl: bool,
    db_url: str | None,
) -> None:
    """Run the design's probes for a participant (those not yet stored) and store each
    probe's trials; print each probe's estimate of the trait it tells.

    \b
    Example:
      study probe run --participant P001
    """
    # lazy: study.probes.measure (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.probes.measure import trait_estimates

    # lazy: study.probes.store (with pandas, pyarrow, sqlalchemy) costs 0.7 s at start-up
    from study.probes.store import probe_frame, run_participant_probes

    for name in only:
        get_probe(name)  # an unknown probe: one line before anything runs
    responder: Responder | None = None
    if driver == "keyboard":
        from study.probes.runner import KeyboardResponder

        responder = KeyboardResponder(
            read_key=input, show=lambda text: click.echo(text, nl=text != ".")
        )
    elif driver == "hardware":
        if port is None:
            raise StudyInputError("--driver hardware without --port; expected the dial unit's port")
        from study.probes.runner import DeviceResponder
        from teleop_core.loop.hardware import HardwareDriver, HardwareError

        try:
            responder = DeviceResponder(exchange=HardwareDriver.open(port).exchange)
        except HardwareError as exc:  # before anything is stored
            raise StudyInputError(
                f"--port {port}: {exc}; expected the serial port of the dial's ESP32, "
                "e.g. /dev/ttyUSB0"
            ) from None
    with opened_database(db_url) as engine, _markers(engine, lsl) as observer:
        if driver == "keyboard":
            stored = run_participant_probes(engine, code, responder, only, observer=observer)
        else:
            with progress_bar() as bar:
                tasks: dict[str, TaskID] = {}

                def progress(name: str, k: int = 0, n: int = 0) -> None:
                    if name not in tasks:
                        tasks[name] = bar.add_task(f"{code} {name}", total=n)
                    bar.update(tasks[name], completed=k)

                stored = run_participant_probes(
                    engine, code, responder, only, progress, observer=observer
                )
        frame = probe_frame(engine)
    mine = frame[frame["participant"] == code]
    if not stored:
        click.echo(f"{code}: every probe of the design is already stored")
    for name, n in stored.items():
        click.echo(f"{code}: {name} {n} trials stored ({driver})")
    if len(mine):
        estimates = trait_estimates(_trials(mine))
        for trait, e in estimates.items():
            click.echo(f"{code}: {trait} {e.value:.4g} (SE {e.se:.2g}, {e.trials} trials)")


@contextmanager
def _markers(engine: Engine, publish: bool) -> Iterator[SessionObserver | None]:
    """The probe trials' marker stream, when --lsl or the design's `[lsl]` says so."""
    # lazy: sqlalchemy.orm costs 0.2 s at start-up
    from sqlalchemy.orm import Session

    # lazy: study.lsl.observers (with sqlalchemy) costs 0.2 s at start-up
    from study.lsl.observers import event_publisher

    # lazy: study.protocol.roster (with sqlalchemy) costs 0.4 s at start-up
    from study.protocol.roster import load_study

    with Session(engine) as session:
        design = load_study(session)[1]
    observer = event_publisher(design, publish)
    try:
        yield observer
    finally:
        if observer is not None:
            observer.close()


def _trials(frame):
    # lazy: study.probes.base (with numpy) costs 69 ms at start-up
    from study.probes.base import ProbeTrial

    return [
        ProbeTrial(
            r.probe,
            int(r.trial_index),
            r.stimulus,
            r.response,
            None if r.correct is None else bool(r.correct),
            r.context,
            r.driver,
        )
        for r in frame.itertuples()
    ]


@probe.command("list")
def list_cmd() -> None:
    """The registered probes: name, the trait each tells, default trials.

    \b
    Example:
      study probe list
    """

    for p in probes():
        click.echo(f"{p.name:<16} {p.trait:<22} {p.default_trials:>3} trials  {p.description}")
