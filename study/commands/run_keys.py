"""The experimenter's keys in `study run` with a physical phantom, on a terminal.

Nothing in the loop sees the guidewire's tip in a physical phantom, so a person says
when it reached the target: the participant with the dial's button
(`teleop_core.loop.hardware.HardwareDriver`), or the experimenter at the terminal
`study run` runs in:

- Enter: the tip reached the target; the trial ends there, completed with success (its
  summary's `end` is "experimenter").
- `x`: stop. The trial stands (`TrialHold`: its samples so far committed, its clock
  standing) while the reason is typed on one line; then it is marked interrupted with
  that reason in the audit log and the session ends, as a signal ends it.

The keys are read only when standard input is a terminal (put in cbreak mode for the
session, restored after it) on a POSIX system; otherwise only the button and the time
limit end a trial.
"""

from __future__ import annotations

import contextlib
import os
import select
import sys
import termios
import threading
import tty
from collections.abc import Callable, Iterator
from typing import IO, Any

from study.protocol.session_settings import TrialHold
from study.protocol.stop_signals import SignalStop

POLL_S = 0.05
"""How often the key reader looks at its stop flag while no key comes, s."""
REACHED_KEYS = ("\r", "\n")
STOP_KEYS = ("x", "X")
STOPPED_BY_EXPERIMENTER = "stopped by the experimenter at the terminal"


class ExperimenterKeys:
    """Reads the experimenter's keys from `stream` (a terminal) in a thread.

    `track(make_driver)` wraps the session's driver factory so the keys reach the trial
    running now; `hold` goes to `run_session`; `stop` is the session's stop event;
    `pause(True/False)` is called around the typed reason (the progress bar set aside
    while the line is typed) and `say(text)` prints a line."""

    def __init__(
        self,
        stream: IO[str],
        stop: SignalStop,
        say: Callable[[str], None],
        pause: Callable[[bool], None] = lambda _: None,
    ) -> None:
        self.stream, self.stop, self.say, self.pause = stream, stop, say, pause
        self.hold = TrialHold()
        self.driver: Any = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._read, name="experimenter-keys", daemon=True)

    def track(self, make_driver: Callable[[], Any]) -> Callable[[], Any]:
        def made() -> Any:
            self.driver = make_driver()
            return self.driver

        return made

    @contextlib.contextmanager
    def reading(self) -> Iterator[ExperimenterKeys]:
        """Within the block, the terminal in cbreak mode and its keys read."""
        fd = self.stream.fileno()
        saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        self._thread.start()
        try:
            yield self
        finally:
            self._done.set()
            self._thread.join()
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)

    def _key(self) -> str | None:
        fd = self.stream.fileno()
        ready, _, _ = select.select([fd], [], [], POLL_S)
        if not ready:
            return None
        data = os.read(fd, 1)
        return data.decode("utf-8", "replace") if data else ""

    def _read(self) -> None:
        while not self._done.is_set():
            key = self._key()
            if key is None:
                continue
            if key == "":  # the terminal closed
                return
            if key in REACHED_KEYS:
                self._reached()
            elif key in STOP_KEYS:
                self._stop()
                return

    def _reached(self) -> None:
        driver = self.driver
        if driver is not None and getattr(driver, "follower", None) is not None:
            driver.reach()
            self.say("reached: the trial ends as completed with success")

    def _stop(self) -> None:
        self.hold.hold()
        self.pause(True)
        fd = self.stream.fileno()
        saved = termios.tcgetattr(fd)
        try:
            cooked = termios.tcgetattr(fd)
            cooked[3] |= termios.ICANON | termios.ECHO
            termios.tcsetattr(fd, termios.TCSADRAIN, cooked)
            sys.stderr.write("study run: the trial stands; why stop it? (one line, Enter) ")
            sys.stderr.flush()
            reason = self._line().strip()
        finally:
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)
            self.pause(False)
        if not self._done.is_set():  # else the session ended while the line was typed
            self.stop.stop_by(
                f"{STOPPED_BY_EXPERIMENTER}: {reason}" if reason else STOPPED_BY_EXPERIMENTER
            )
        self.hold.release()

    def _line(self) -> str:
        """One typed line (waiting with the key reader's poll, so the session's end
        does not wait on a line that never comes)."""
        chars: list[str] = []
        while not self._done.is_set():
            key = self._key()
            if key is None:
                continue
            if key in ("", "\n", "\r"):
                break
            chars.append(key)
        return "".join(chars)


def experimenter_keys(
    stream: IO[str] | None,
    stop: SignalStop,
    say: Callable[[str], None],
    pause: Callable[[bool], None] = lambda _: None,
) -> ExperimenterKeys | None:
    """The keys on `stream` if it is a terminal; None otherwise."""
    if stream is None:
        return None
    try:
        if not os.isatty(stream.fileno()):
            return None
    except (AttributeError, OSError, ValueError):  # a stream without a descriptor
        return None
    return ExperimenterKeys(stream, stop, say, pause)
