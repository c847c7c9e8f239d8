"""The observers a session (or a probe run, or the terminal app) gets from its design's
`[lsl]` table and the `--lsl` flag."""

from __future__ import annotations

from collections.abc import Callable

from sqlalchemy import Engine

from study.protocol.design import StudyDesign
from study.protocol.observer import LastingObserver, Observers, SessionObserver

SUBSCRIBE_S = 5.0
"""How long a short command (a probe run) waits for a recorder to subscribe to its
marker stream before its first marker, s (what is pushed before reaches no one)."""


def session_observers(
    engine: Engine,
    design: StudyDesign,
    publish: bool = False,
    notice: Callable[[str], None] = lambda _: None,
) -> SessionObserver | None:
    """A publisher when `publish` or the design says so, a recorder of the design's
    streams when it names any; None when neither (pylsl is then never loaded)."""
    observers: list[SessionObserver] = []
    if publish or design.lsl.publish:
        from study.lsl.publish import Publisher

        observers.append(Publisher())
    if design.lsl.record:
        from study.lsl.record import Recorder

        observers.append(Recorder(engine, design.lsl.record, notice))
    return Observers(observers) if observers else None


def event_publisher(
    design: StudyDesign, publish: bool = False, wait_for_consumers_s: float | None = None
) -> LastingObserver | None:
    """The markers of what happens outside a session's trials (probe trials, a stored
    questionnaire), when `publish` or the design says so; None otherwise. The caller
    closes it (`LastingObserver.close`) when done. `wait_for_consumers_s`: the
    publisher's (`SUBSCRIBE_S` by default)."""
    if not (publish or design.lsl.publish):
        return None
    # lazy: study.lsl.publish (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.lsl.publish import Publisher

    wait_s = SUBSCRIBE_S if wait_for_consumers_s is None else wait_for_consumers_s
    # markers only: no trial runs here, and a sample stream no recorder subscribes to
    # would hold the start for the whole wait
    return LastingObserver(Publisher(wait_for_consumers_s=wait_s, sample_streams=False))


def lasting_observers(
    engine: Engine,
    design: StudyDesign,
    publish: bool = False,
    notice: Callable[[str], None] = lambda _: None,
) -> LastingObserver | None:
    """`session_observers` for a program that runs many sessions (the terminal app, one
    per trial), kept open across them until `close()`; None when the design has no
    streams and `publish` is off."""
    observer = session_observers(engine, design, publish, notice)
    return None if observer is None else LastingObserver(observer)
