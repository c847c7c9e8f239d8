"""What a session is run with (`SessionSettings`), each value checked once, as it is made.

The session runner (`study.protocol.session.run_session`) takes one of these beside the
participant's code and the observer it tells its events to; what the callers know
before a session starts (the driver, the estimator, the pace, who runs it, how it is
stopped) is here, checked where it enters rather than again inside the runner.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from study.errors import StudyInputError

if TYPE_CHECKING:
    from study.protocol.design import StudyDesign
    from study.protocol.participant_model import ParticipantModel
    from teleop_core.estimation.estimator import ForceEstimator
    from teleop_core.loop.drivers import Driver


class TrialHold:
    """Holds a running trial between two steps while someone decides, then lets it go on
    (the terminal app's stop dialog: the trial stands while its reason is typed).

    `hold()` and `release()` from any thread. At its next step a held trial commits the
    samples it has (a crash while it stands loses none of them) and waits in
    `wait()` until released. The time it stands is not trial time: the loop's clock
    stands with it, and a paced trial goes on at its pace from where it stood rather
    than catching the held seconds up. `on_release`, called in the trial's thread as it
    goes on, may raise to end the trial there (a stop decided while it stood)."""

    def __init__(self, on_release: Callable[[], None] = lambda: None) -> None:
        self._go = threading.Event()
        self._go.set()
        self._on_release = on_release
        self.standing = threading.Event()
        """Set while the trial waits, its samples so far committed."""

    @property
    def held(self) -> bool:
        return not self._go.is_set()

    def hold(self) -> None:
        self._go.clear()

    def release(self) -> None:
        self._go.set()

    def wait(self) -> float:
        """In the trial's thread: wait while held; the seconds waited."""
        start = time.monotonic()
        self.standing.set()
        try:
            self._go.wait()
        finally:
            self.standing.clear()
        waited = time.monotonic() - start
        self._on_release()
        return waited


@dataclass(frozen=True)
class SessionSettings:
    """A session's settings; StudyInputError (one line) for a value out of its range."""

    driver_kind: str
    """Who drives the trials, as stored with each trial: `simulated`, `hardware`,
    `keyboard`."""
    estimator: ForceEstimator
    make_driver: Callable[[], Driver] | None = None
    """Opens each trial's driver; None: the participant's simulated person."""
    pace: float | None = None
    """Times real time of a simulated session (to watch it, or stop it in the middle);
    None: as fast as it goes."""
    max_trials: int | None = None
    """At most this many of the participant's remaining trials; None: all of them."""
    actor: str | None = None
    """Who runs the session, recorded with the lease and the audit entries."""
    stop: threading.Event | None = None
    """Set, it ends the session at its next step, the running trial interrupted."""
    participants: ParticipantModel | None = None
    """The fitted model simulated people are drawn from (else the group's profiles)."""
    hold: TrialHold | None = None
    """Lets another thread hold the running trial between two steps."""
    design: StudyDesign | None = None
    """The study's design as the caller already read it from the same database (for
    its `[lsl]` or `[sensors]` tables), so a session reads it once; None: the runner
    reads it."""
    wait_out_storage: bool = False
    """A watched session: a lock held by another program does not stop the trial; up to
    `study.protocol.session.HOLD_S` of its samples wait in memory (`SampleWriter`'s
    `hold_s`) and the observer's `storage_wait` is told while they do."""

    def __post_init__(self) -> None:
        pace = self.pace
        if pace is not None and not (
            isinstance(pace, int | float) and math.isfinite(pace) and pace > 0
        ):
            raise StudyInputError(f"pace {pace!r}; expected a finite number > 0 (times real time)")
        n = self.max_trials
        if n is not None and not (isinstance(n, int) and n >= 0):
            raise StudyInputError(f"max_trials {n!r}; expected a whole number >= 0")
