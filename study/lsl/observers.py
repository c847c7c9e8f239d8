"""The observers a session gets from its design's `[lsl]` table and the `--lsl` flag."""

from __future__ import annotations

from collections.abc import Callable

from sqlalchemy import Engine

from study.protocol.design import StudyDesign
from study.protocol.observer import Observers, SessionObserver


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
