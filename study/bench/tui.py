"""`study bench tui`: how long the terminal app takes to show the overview.

Starts the real `study tui --db URL` in a pseudo-terminal (80 x 24) and times from the
process's start to the moment the overview's progress line ("Sessions done") reaches
the terminal, then quits it with ctrl+q (timed to the exit). Further runs time F3 to a
run screen ready to start a trial, and ctrl+q while it is still preparing. This counts
everything a user waits for: the interpreter, the imports, the database's schema check,
the roster query and the first paint. The standard library's `pty` does the terminal
(pexpect is only a test dependency).
"""

from __future__ import annotations

import fcntl
import os
import pty
import resource
import select
import statistics
import struct
import subprocess
import termios
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

from study.bench.startup import study_command
from study.errors import StudyInputError

MARKER = b"Sessions done"
TARGET_S = 1.5
"""The target: the overview within 1.5 s of starting."""


@dataclass(frozen=True)
class TuiBenchResult:
    seconds: list[float]
    """Start to overview, one per run, s."""
    median_s: float
    participants: int
    cpu_seconds: list[float]
    """CPU time of each run's process from start to exit, s (less sensitive than the wall
    time to other jobs on the machine)."""
    app_seconds: list[float]
    """The app's own part: from building it to the overview with data, in this process
    (headless, imports done), s."""
    quit_seconds: list[float] = field(default_factory=list)
    """ctrl+q on the overview to the process's exit, s."""
    run_ready_seconds: list[float] = field(default_factory=list)
    """F3 to the run screen ready ("status: idle" after preparing the simulation), s."""
    quit_preparing_seconds: list[float] = field(default_factory=list)
    """ctrl+q while the run screen prepares the simulation, to the exit, s."""
    target_s: float = TARGET_S

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


class _Terminal:
    """`study tui --db URL` on a pseudo-terminal of 80 x 24, read as it draws."""

    def __init__(self, db_url: str) -> None:
        self.db_url = db_url
        self.master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
        env = {**os.environ, "TERM": "xterm-256color"}
        self.start = time.monotonic()
        self.proc = subprocess.Popen(
            [*study_command(), "tui", "--db", db_url],
            stdin=slave,
            stdout=slave,
            stderr=slave,
            env=env,
            close_fds=True,
        )
        os.close(slave)
        self.seen = b""

    def wait_for(self, marker: bytes, timeout_s: float = 60.0) -> float:
        """Read until `marker` is drawn; the time it took since the process started."""
        self.seen = b""
        while marker not in self.seen:
            if time.monotonic() - self.start > timeout_s + 60.0:
                raise StudyInputError(
                    f"`study tui --db {self.db_url}` never drew {marker.decode()!r}; "
                    "expected a study database"
                )
            ready, _, _ = select.select([self.master], [], [], 0.05)
            if ready:
                try:
                    self.seen = self.seen[-64:] + os.read(self.master, 65536)
                except OSError:  # the app ended (its terminal closed)
                    raise StudyInputError(
                        f"`study tui --db {self.db_url}` ended before drawing {marker.decode()!r}"
                    ) from None
        return time.monotonic() - self.start

    def press(self, keys: bytes) -> float:
        os.write(self.master, keys)
        return time.monotonic()

    def quit(self) -> float:
        """ctrl+q; seconds until the process has exited."""
        t0 = self.press(b"\x11")
        _drain_until_exit(self.proc, self.master)
        return time.monotonic() - t0

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        os.close(self.master)


F3 = b"\x1bOR"
PREPARING = b"preparing the simulation"
READY = b"status: idle"


def time_to_overview(db_url: str, timeout_s: float = 60.0) -> tuple[float, float, float]:
    """(seconds from starting `study tui --db db_url` to the overview on its terminal,
    seconds from ctrl+q to the process's exit, CPU seconds of the whole run)."""
    cpu0 = _children_cpu_s()
    term = _Terminal(db_url)
    try:
        elapsed = term.wait_for(MARKER, timeout_s)
        quit_s = term.quit()
    finally:
        term.close()
    return elapsed, quit_s, _children_cpu_s() - cpu0


def time_run_screen(db_url: str, quit_while_preparing: bool) -> float:
    """F3 from the overview: seconds until the run screen has prepared the simulation
    (estimator loaded, loop compiled or read from its cache) and says idle; or, with
    `quit_while_preparing`, seconds from ctrl+q during the preparation to the exit."""
    term = _Terminal(db_url)
    try:
        term.wait_for(MARKER)
        t0 = term.press(F3)
        term.wait_for(PREPARING)
        if quit_while_preparing:
            return term.quit()
        term.wait_for(READY)
        ready_s = time.monotonic() - t0
        term.quit()
        return ready_s
    finally:
        term.close()


def _drain_until_exit(proc: subprocess.Popen, master: int, timeout_s: float = 20.0) -> None:
    """Read the terminal until the app exits (a full pty would block its last writes)."""
    end = time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < end:
        ready, _, _ = select.select([master], [], [], 0.05)
        if ready:
            try:
                os.read(master, 65536)
            except OSError:
                break
    proc.wait(timeout=max(end - time.monotonic(), 1.0))


def bench_tui(db_url: str, app_seconds: Callable[[str], float], runs: int = 5) -> TuiBenchResult:
    """`runs` starts of `study tui` on a terminal, and `runs` of the app's own part
    (`app_seconds(db_url)`: make_app to the overview, `study.tui.probes`)."""
    # lazy: db.migrate (with sqlalchemy) costs 0.2 s at start-up
    from db.migrate import open_database

    # lazy: study.protocol.roster (with sqlalchemy) costs 0.4 s at start-up
    from study.protocol.roster import schedule

    engine = open_database(db_url, create=False)
    try:
        participants = len(schedule(engine)["participants"])
    finally:
        engine.dispose()
    runs_s = [time_to_overview(db_url) for _ in range(runs)]
    seconds = [wall for wall, _, _ in runs_s]
    return TuiBenchResult(
        seconds,
        statistics.median(seconds),
        participants,
        [cpu for _, _, cpu in runs_s],
        [app_seconds(db_url) for _ in range(runs)],
        quit_seconds=[q for _, q, _ in runs_s],
        run_ready_seconds=[time_run_screen(db_url, False) for _ in range(runs)],
        quit_preparing_seconds=[time_run_screen(db_url, True) for _ in range(runs)],
    )
