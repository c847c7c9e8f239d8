"""How long work tells how far it has come: one protocol for every progress callback.

Long work (a session, training, a calibration, a fit, an export, a bench) takes a
`progress` argument of type `Progress` and calls it with the step it is on and, where
the work can be counted, how many of how many units are done:

    progress("training the GRU")                # a step that cannot be counted
    progress("epoch 3: validation RMSE 0.041 N", 3, 100)
    progress("samples", 120, 288)

`total` is 0 when the step is not counted. The caller decides what to show (a Rich
progress bar on the command line, a status line in the terminal app, nothing in a
test); `no_progress` is the default that shows nothing, and `describe` the one-line
form of a call. It lives in `teleop_core` (plain Python, no dependency) so that the
numerics and the application share it.

Where the output is no terminal (a pipe, a log file of a scripted run), a bar or a
spinner draws nothing; `Heartbeat` writes one plain line every `interval_s` instead,
from a thread of its own so that a step that reports nothing for a while still shows
that the work is alive. Its clock is passed in, so its timing is tested without waiting.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol, Self

__all__ = [
    "HEARTBEAT_S",
    "Heartbeat",
    "Progress",
    "as_step",
    "clock_text",
    "describe",
    "no_progress",
]

HEARTBEAT_S = 10.0
"""Seconds between two progress lines where the output is no terminal."""


class Progress(Protocol):
    """A progress callback: `progress(step, done=0, total=0)`.

    `step` says what runs now in one short line (e.g. ``"round 2: stribeck"``), `done`
    how many units of it are done and `total` how many it has (0: not counted). The
    arguments are passed by position, so a function or lambda with other parameter
    names is a `Progress` too.
    """

    def __call__(self, step: str, done: int = 0, total: int = 0, /) -> None:
        """Tell how far the work has come.

        Parameters
        ----------
        step : str
            What runs now, one short line.
        done : int, optional
            Units of the step done so far.
        total : int, optional
            Units the step has in all; 0 when it is not counted.
        """


def no_progress(step: str, done: int = 0, total: int = 0) -> None:
    """The `Progress` that shows nothing (the default of every long function).

    Parameters
    ----------
    step : str
        What runs now (ignored).
    done : int, optional
        Units of the step done so far (ignored).
    total : int, optional
        Units the step has in all (ignored).
    """


def describe(step: str, done: int = 0, total: int = 0) -> str:
    """One line for a call of a `Progress`.

    Parameters
    ----------
    step : str
        What runs now.
    done : int, optional
        Units of the step done so far.
    total : int, optional
        Units the step has in all; 0 when it is not counted.

    Returns
    -------
    str
        ``"step (done/total)"`` when the step is counted, else ``"step"``.

    Examples
    --------
    >>> describe("samples", 3, 10)
    'samples (3/10)'
    >>> describe("compiling the loop")
    'compiling the loop'
    """
    return f"{step} ({done}/{total})" if total else step


def as_step(progress: Progress, step: str) -> Progress:
    """`progress` told every call as `step` (keeping the count): for a part of larger
    work that the caller names.

    Parameters
    ----------
    progress : Progress
        The `Progress` to tell.
    step : str
        The step every call is told as, whatever step the caller gives.

    Returns
    -------
    Progress
        A `Progress` passing each call's count on to `progress` under `step`.

    Examples
    --------
    >>> seen = []
    >>> as_step(lambda s, d=0, t=0: seen.append((s, d, t)), "emulator")("trial", 2, 5)
    >>> seen
    [('emulator', 2, 5)]
    """

    def told(_step: str, done: int = 0, total: int = 0) -> None:
        progress(step, done, total)

    return told


def clock_text(seconds: float) -> str:
    """A duration for people: ``"45 s"``, ``"3 min 20 s"``, ``"1 h 05 min"``.

    Examples
    --------
    >>> clock_text(45.2), clock_text(200), clock_text(3900)
    ('45 s', '3 min 20 s', '1 h 05 min')
    """
    whole = round(seconds)
    if whole < 60:
        return f"{whole} s"
    if whole < 3600:
        return f"{whole // 60} min {whole % 60:02d} s"
    return f"{whole // 3600} h {whole % 3600 // 60:02d} min"


class Heartbeat:
    """One progress line every `interval_s` on a stream that is no terminal.

    A `Heartbeat` is a `Progress` (calling it records the step and its count) and a
    context manager: inside its block a daemon thread writes `line(now)` every
    `interval_s` seconds, the first `interval_s` after the start, whether or not the
    work has reported since. The line says what is done and what remains
    (``"demo: sessions 12/36, 24 to go; 1 min 40 s elapsed, about 3 min 20 s left"``).

    Parameters
    ----------
    write : callable
        Writes one line (e.g. ``print`` to stderr).
    label : str, optional
        What the work is, at the head of each line.
    interval_s : float, optional
        Seconds between two lines.
    clock : callable, optional
        Monotonic seconds (``time.monotonic``; a fake one in tests).
    summary : callable, optional
        The line's body instead of the last recorded step (a progress bar's tasks).
    """

    def __init__(
        self,
        write: Callable[[str], None],
        label: str = "",
        interval_s: float = HEARTBEAT_S,
        clock: Callable[[], float] = time.monotonic,
        summary: Callable[[], str] | None = None,
    ) -> None:
        self.write = write
        self.label = label
        self.interval_s = interval_s
        self.clock = clock
        self.summary = summary
        self.step, self.done, self.total = "starting", 0, 0
        self.started_s = clock()
        self.last_s = self.started_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __call__(self, step: str, done: int = 0, total: int = 0, /) -> None:
        self.step, self.done, self.total = step, done, total

    def update(self, text: str) -> None:
        """Record a step without a count (the interface of a Rich status line)."""
        self(text)

    def line(self, now: float) -> str:
        """What is done and what remains, and the time taken so far."""
        elapsed = now - self.started_s
        if self.summary is not None:
            body = self.summary()
        elif self.total:
            left = max(self.total - self.done, 0)
            body = f"{self.step}: {self.done}/{self.total} done, {left} to go"
        else:
            body = self.step
        timing = f"{clock_text(elapsed)} elapsed"
        if self.summary is None and self.total and 0 < self.done < self.total:
            timing += f", about {clock_text(elapsed * (self.total - self.done) / self.done)} left"
        head = f"{self.label}: " if self.label else ""
        return f"{head}{body}; {timing}"

    def poll(self) -> bool:
        """Write a line if `interval_s` has passed since the last; whether it wrote."""
        now = self.clock()
        if now - self.last_s < self.interval_s:
            return False
        self.last_s = now
        self.write(self.line(now))
        return True

    def _beat(self) -> None:
        while not self._stop.wait(max(self.interval_s - (self.clock() - self.last_s), 0.05)):
            self.poll()

    def __enter__(self) -> Self:
        self.started_s = self.last_s = self.clock()
        self._stop.clear()
        self._thread = threading.Thread(target=self._beat, name="progress-lines", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
