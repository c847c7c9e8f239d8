"""A session ended by a termination signal: its running trial interrupted, not left running.

A `study run` that is killed (`kill PID`, a closed terminal, a logged-out SSH session)
gets SIGTERM or SIGHUP. Left to Python's defaults the process ends at once and its trial
stays `running` until the participant's next session recovers it. `stop_on_signals`
replaces those handlers, for the length of the session, with one that only sets the
session's stop event and names the signal (`SignalStop.reason`); the session runner
checks the event at every step (a real device's or a paced session's 50 ms, an unpaced
simulation's chunk), marks the trial `interrupted` with that reason in the audit log,
releases its lease and returns, and `study run` ends with one line and status 128 + the
signal's number, as a shell reports a process a signal ended.

The handler sets a flag and nothing else (a signal can arrive in the middle of a
database write, which must finish); a second signal of the same kind, for a session
that does not stop, gets the default handler back and ends the process at once. A
`kill -9` cannot be caught: `study.protocol.orphans` covers it for the readers.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

STOP_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name)
)
"""The signals a session ends on, its trial interrupted (Windows has no SIGHUP)."""


class SignalStop(threading.Event):
    """A session's stop event that records which signal set it."""

    def __init__(self) -> None:
        super().__init__()
        self.signum: int | None = None
        self._reason: str | None = None

    @property
    def reason(self) -> str:
        """The audit log's reason for the trial the signal (or a person) interrupted."""
        if self._reason is not None:
            return self._reason
        name = signal.Signals(self.signum).name if self.signum is not None else "a signal"
        return f"the session stopped on {name}: its `study run` process was ended"

    @property
    def exit_status(self) -> int:
        """128 + the signal's number, as a shell reports a process ended by it; 1 for a
        session a person stopped (`stop_by`)."""
        if self._reason is not None and self.signum is None:
            return 1
        return 128 + (self.signum or 0)

    def stop_by(self, reason: str) -> None:
        """A person stops the session (the experimenter's `x` in `study run`): `reason`
        is the audit log's for the trial it interrupts."""
        self._reason = reason
        self.set()

    def on_signal(self, signum: int, frame: FrameType | None) -> None:
        self.signum = signum
        self.set()
        signal.signal(signum, signal.SIG_DFL)  # a second one ends the process at once


def stop_reason(stop: threading.Event | None, default: str) -> str:
    """Why the session's `stop` ended its trial: the signal's, or `default`."""
    return stop.reason if isinstance(stop, SignalStop) and stop.is_set() else default


@contextmanager
def stop_on_signals(signals: tuple[int, ...] = STOP_SIGNALS) -> Iterator[SignalStop]:
    """Within the block, `signals` set the returned event instead of ending the process;
    the previous handlers come back after it. Only from the main thread (Python's rule
    for signal handlers)."""
    stop = SignalStop()
    previous = {signum: signal.signal(signum, stop.on_signal) for signum in signals}
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
