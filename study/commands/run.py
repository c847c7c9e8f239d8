"""`study run`: a participant's session, headless."""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskID, TextColumn

from db.migrate import open_database
from study.commands.base import (
    StudyCommand,
    actor_option,
    db_option,
    load_participants,
    participants_option,
    progress_bar,
)
from study.errors import StudyInputError
from study.protocol.actor import current_actor
from study.protocol.roster import read_design, schedule
from study.protocol.stop_signals import stop_on_signals

MIN_PACE, MAX_PACE = 0.01, 1000.0
"""--pace's range: a hundredth of real time (a 30 s trial in under an hour) to a thousand
times (beyond it, as fast as it goes is the same)."""
MAX_JOBS = 64

if TYPE_CHECKING:
    from sqlalchemy import Engine

    from study.commands.run_keys import ExperimenterKeys
    from study.protocol.design import StudyDesign
    from study.protocol.design_sensors import SensorSettings
    from study.protocol.observer import PendingTrial, SessionObserver, TrialInfo
    from study.protocol.participant_model import ParticipantModel
    from study.protocol.stop_signals import SignalStop
    from teleop_core.loop.follower_units import ForceSource, PhysicalFollower
    from teleop_core.loop.hardware import HardwareDriver


@click.command("run", cls=StudyCommand)
@click.option("--participant", "code", default=None, help="Participant code, e.g. P003.")
@click.option(
    "--all", "run_all", is_flag=True, help="Every enrolled participant's remaining trials."
)
@click.option(
    "--jobs",
    type=click.IntRange(1, MAX_JOBS),
    default=None,
    help="Processes running participants side by side (with --all) [default: 1].",
)
@click.option(
    "--driver",
    type=click.Choice(["simulated", "keyboard", "hardware"]),
    default="simulated",
    show_default=True,
    help="Who drives the trials: a simulated participant, a person on the keyboard, or a "
    "person on the dial (--port).",
)
@click.option("--port", help="Serial port of the dial's ESP32 (hardware driver).")
@click.option(
    "--drive-port",
    help="Serial port of the guidewire drive's ESP32 (hardware driver): the real follower "
    "in a physical phantom, its forces from the design's [sensors] unit.",
)
@click.option(
    "--pace",
    type=click.FloatRange(min=MIN_PACE, max=MAX_PACE),
    help="Run a simulated session at this many times real time [default: as fast as it goes].",
)
@click.option(
    "--lsl",
    is_flag=True,
    help="Publish the session's markers and samples as Lab Streaming Layer streams (as "
    "`[lsl] publish = true` in the design does); needs LSLAPICFG (see `study lsl-config`).",
)
@participants_option
@actor_option
@db_option
def run(
    code: str | None,
    run_all: bool,
    jobs: int | None,
    driver: str,
    port: str | None,
    pace: float | None,
    participants_path: Path | None,
    actor: str | None,
    db_url: str | None,
    lsl: bool = False,
    drive_port: str | None = None,
) -> None:
    """Run the participant's remaining scheduled trials and store every sample.

    One session per participant: while one runs (here or on another machine sharing the
    database), a second is refused; one whose process died is taken over.

    With --drive-port the phantom is the physical one, and a person says when the tip
    has reached the target: the dial's button, or Enter at this terminal (the trial
    completed with success); `x` here stops the trial, with a reason typed. A trial
    that reaches the time limit is stored with success false. The summary's `end`
    says which (button, experimenter, time_limit). The keys are read only when
    standard input is a terminal.

    \b
    Example:
      study run --participant P001 --driver hardware --port /dev/ttyUSB0
      study run --participant P001 --driver hardware --port /dev/ttyUSB0 \\
          --drive-port /dev/ttyUSB1     # and the real drive ([sensors] in the design)
      study run --all     # every participant, simulated
    """
    _check_options(code, run_all, jobs)
    who = current_actor(actor)
    model = load_participants(participants_path)
    if model is not None and driver != "simulated":
        raise StudyInputError(
            f"--participants with --driver {driver}; expected --driver "
            "simulated (a fitted model draws simulated people)"
        )
    if run_all:
        if lsl:
            raise StudyInputError(
                "--lsl with --all; expected --participant CODE (one "
                "session at a time publishes its streams)"
            )
        if driver != "simulated":
            raise StudyInputError(f"--all runs simulated participants; got --driver {driver}")
        _run_all(db_url, jobs or 1, pace, who, participants_path)
        return
    assert code is not None  # _check_options: --participant CODE without --all
    _run_participant(code, driver, port, drive_port, pace, lsl, who, model, db_url)


def _run_participant(
    code: str,
    driver: str,
    port: str | None,
    drive_port: str | None,
    pace: float | None,
    lsl: bool,
    who: str,
    model: ParticipantModel | None,
    db_url: str | None,
) -> None:
    """One participant's session, its progress on a bar and its streams as the design
    and --lsl say."""
    # lazy: study.protocol.default_estimator (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.protocol.default_estimator import load_estimator

    # lazy: study.protocol.session (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.protocol.session import run_session
    from study.protocol.session_settings import SessionSettings

    if driver == "keyboard":
        raise StudyInputError("the keyboard driver needs the terminal app; expected `study tui`")
    if drive_port is not None and driver != "hardware":
        raise StudyInputError(
            f"--drive-port with --driver {driver}; expected --driver hardware (the drive "
            "unit joins the dial unit)"
        )
    if driver == "hardware" and not port:
        raise StudyInputError("--driver hardware needs --port, e.g. --port /dev/ttyUSB0")

    # lazy: study.protocol.parallel (multiprocessing) costs 20 ms at start-up
    from study.protocol.parallel import compile_loop_once

    engine = open_database(db_url, create=False)
    started: list[PendingTrial] = []
    try:
        design = read_design(engine)  # read once: its [sensors], its [lsl], the session's
        make_driver = None
        if port is not None and driver == "hardware":
            make_driver = _hardware_driver(port, drive_port, design.sensors)
        estimator = load_estimator()
        with stop_on_signals() as stop, _progress() as progress:
            bar = progress.add_task(f"session {code}", total=None)
            compile_loop_once(lambda m: progress.console.print(f"study run: {m}", markup=False))

            observer = _lsl_observers(engine, design, lsl, progress)
            observer = _with_progress(observer, progress, bar, code, started)
            if drive_port is not None:
                observer = _with_end_notice(observer, progress)
            keys = _experimenter_keys(drive_port, stop, progress)
            with keys.reading() if keys is not None else contextlib.nullcontext():
                settings = SessionSettings(
                    driver,
                    estimator,
                    keys.track(make_driver) if keys and make_driver else make_driver,
                    pace,
                    actor=who,
                    stop=stop,
                    participants=model,
                    hold=keys.hold if keys is not None else None,
                    design=design,
                )
                done = run_session(engine, code, settings, observer)
    finally:
        engine.dispose()
    if stop.is_set():
        click.echo(_stopped_line(code, stop, started, len(done)), err=True)
        raise click.exceptions.Exit(stop.exit_status)
    click.echo(f"{code}: {len(done)} trials completed and stored")


def _check_options(code: str | None, run_all: bool, jobs: int | None) -> None:
    """One line for options that cannot go together, before anything runs."""
    if (code is None) == (not run_all):
        raise StudyInputError("give --participant CODE or --all; expected exactly one")
    if jobs is not None and not run_all:
        raise StudyInputError(
            f"--jobs {jobs} with --participant; expected --all (one "
            "participant's session runs in one process)"
        )


def _with_progress(
    observer: SessionObserver | None,
    progress: Progress,
    bar: TaskID,
    code: str,
    started: list[PendingTrial],
) -> SessionObserver:
    """`observer` and the bar's line: the trial running now, and k of n done; each trial
    as it comes appended to `started` (for the line of a stopped session)."""
    # lazy: study.protocol.observer costs 3 ms at start-up
    from study.protocol.observer import Observers, SessionObserver

    class Report(SessionObserver):
        def trial_progress(self, pending: PendingTrial, k: int, n: int) -> None:
            started.append(pending)
            kind = "practice" if pending.practice else "trial"
            progress.update(
                bar,
                total=n,
                completed=k,
                description=f"{code} {pending.block.task}/{pending.block.condition} "
                f"{kind} {pending.trial_index + 1}",
            )

    return Observers([o for o in (Report(), observer) if o is not None])


def _with_end_notice(observer: SessionObserver | None, progress: Progress) -> SessionObserver:
    """`observer` and a line above the bar for each physical-phantom trial that reached
    the time limit (stored with success false: no one said the tip reached the target)."""
    # lazy: study.protocol.observer costs 3 ms at start-up
    from study.protocol.observer import Observers, SessionObserver

    class EndNotice(SessionObserver):
        def trial_ended(self, trial: TrialInfo, status: str, outcome: dict[str, Any]) -> None:
            if status != "completed" or outcome.get("end") != "time_limit":
                return
            kind = "practice trial" if trial.practice else "trial"
            progress.console.print(
                f"study run: {trial.task.name}/{trial.condition} {kind} "
                f"{trial.trial_index + 1} reached the time limit: stored with success "
                "false (neither the dial's button nor Enter said the tip reached the target)",
                markup=False,
            )

    return Observers([o for o in (observer, EndNotice()) if o is not None])


def _experimenter_keys(
    drive_port: str | None, stop: SignalStop, progress: Progress
) -> ExperimenterKeys | None:
    """With a physical phantom (--drive-port) and a terminal on stdin, the
    experimenter's keys: Enter ends the trial as reached, `x` stops it."""
    if drive_port is None:
        return None
    try:
        from study.commands.run_keys import experimenter_keys
    except ImportError:  # no POSIX terminal (Windows): the button and the time limit
        return None

    def say(message: str) -> None:
        progress.console.print(f"study run: {message}", markup=False)

    def pause(typing: bool) -> None:
        progress.stop() if typing else progress.start()

    keys = experimenter_keys(sys.stdin, stop, say, pause)
    if keys is not None:
        say(
            "the physical phantom's trials end at the dial's button, or here: Enter when "
            "the tip has reached the target, x to stop the trial"
        )
    return keys


def _hardware_driver(
    port: str, drive_port: str | None, sensors: SensorSettings
) -> Callable[[], HardwareDriver]:
    """Opens the units for each trial: the dial on `port`, and given `drive_port` the
    drive and the design's forces unit `sensors` (refused, before anything runs, if the
    design names none)."""
    # lazy: teleop_core.loop.hardware (with serial, numpy) costs 74 ms at start-up
    from teleop_core.loop.hardware import HardwareDriver, HardwareError

    if drive_port is not None:
        if sensors.source is None:
            raise StudyInputError(
                f"--drive-port {drive_port}: the study's design names no force sensors; "
                'expected a [sensors] table (source = "serial", port = "...") for the '
                "physical phantom's forces"
            )

    def make_driver() -> HardwareDriver:
        try:
            dial = HardwareDriver.open(port)
        except HardwareError as exc:  # before the trial's row: nothing is written
            raise StudyInputError(
                f"--port {port}: {exc}; expected the serial port of the dial's ESP32, "
                "e.g. /dev/ttyUSB0"
            ) from None
        if drive_port is None:
            return dial
        try:
            dial.follower = _open_follower(drive_port, sensors)
        except BaseException:
            dial.close()
            raise
        return dial

    return make_driver


def _open_follower(drive_port: str, sensors: SensorSettings) -> PhysicalFollower:
    """The drive unit and the design's force sensors; one line if either fails."""
    # lazy: teleop_core.loop.follower_units (with serial, numpy) costs 79 ms at start-up
    from teleop_core.loop.follower_units import PhysicalFollower

    # lazy: teleop_core.loop.hardware (with serial, numpy) costs 74 ms at start-up
    from teleop_core.loop.hardware import HardwareError

    def open_stream() -> ForceSource:
        # lazy: study.lsl.forces (with serial, numpy) costs 87 ms at start-up
        from study.lsl.forces import LslForces

        return LslForces(sensors.stream, sensors.proximal_channel, sensors.distal_channel)

    forces = open_stream if sensors.source == "lsl" else sensors.port
    try:
        return PhysicalFollower.open(drive_port, forces)
    except HardwareError as exc:
        where = f"--drive-port {drive_port}" if drive_port in str(exc) else "[sensors]"
        raise StudyInputError(
            f"{where}: {exc}; expected the drive's ESP32 on --drive-port and "
            f"{sensors.where} as the design's [sensors] names"
        ) from None


def _stopped_line(code: str, stop: SignalStop, started: list[PendingTrial], done: int) -> str:
    """What a session a signal stopped did: the trial it interrupted, what it kept."""
    kept = f"{done} trial(s) completed and stored"
    if len(started) > done:
        item = started[-1]
        kind = "practice" if item.practice else "trial"
        kept += (
            f"; {code}'s {item.block.task}/{item.block.condition} {kind} "
            f"{item.trial_index + 1} marked interrupted, its samples kept"
        )
    return (
        f"study run: {code}: {stop.reason}; {kept}; `study run --participant {code}` "
        "goes on from there"
    )


def _lsl_observers(
    engine: Engine, design: StudyDesign, publish: bool, progress: Progress
) -> SessionObserver | None:
    """The design's `[lsl]` streams (and --lsl's), their notices printed above the bar."""
    # lazy: study.lsl.observers costs 4 ms at start-up
    from study.lsl.observers import session_observers

    def notice(message: str) -> None:
        progress.console.print(f"study run: {message}", markup=False)

    return session_observers(engine, design, publish, notice)


def _progress() -> Progress:
    """The bar both run modes show on stderr: what runs now, and k of n done."""
    return progress_bar(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn())


def _lsl_notice(design: StudyDesign) -> None:
    """Say that --all leaves the design's `[lsl]` table aside."""
    if design.lsl.publish or design.lsl.record:
        click.echo(
            "study run: the design's [lsl] streams are published and recorded by one "
            "participant's session (--participant CODE), not by --all",
            err=True,
        )


def _run_all(
    db_url: str | None, jobs: int, pace: float | None, actor: str, participants: Path | None
) -> None:
    # lazy: study.protocol.parallel (multiprocessing) costs 20 ms at start-up
    from study.protocol.parallel import run_participants

    engine = open_database(db_url, create=False)
    try:
        design = read_design(engine)  # read once, here: the notice, the roster, every session
        codes = [p["code"] for p in schedule(engine, design)["participants"] if not p["withdrawn"]]
    finally:
        engine.dispose()
    _lsl_notice(design)
    start = time.monotonic()
    total = 0
    busy: list[str] = []
    with _progress() as progress:
        bar = progress.add_task("participants", total=len(codes))

        def skipped(code: str, message: str) -> None:
            busy.append(code)
            progress.console.print(f"study run: skipped: {message}", markup=False)

        model = str(participants) if participants is not None else None

        def notice(message: str) -> None:
            progress.console.print(f"study run: {message}", markup=False)

        runs = run_participants(
            db_url, codes, jobs, pace, actor, skipped, model, notice, design=design
        )
        for code, n in runs:
            total += n
            progress.update(bar, advance=1, description=f"participants ({code} done)")
    if busy:
        click.echo(
            f"{len(busy)} participant(s) skipped, their sessions running elsewhere: "
            + ", ".join(busy),
            err=True,
        )
    click.echo(
        f"{len(codes)} participants, {total} trials completed and stored in "
        f"{time.monotonic() - start:.1f} s with {jobs} process(es)"
    )
