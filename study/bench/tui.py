"""`study bench tui`: how long the terminal app takes to show the overview.

Starts the real `study tui --db URL` in a pseudo-terminal (80 x 24) and times from the
process's start to the moment the overview's progress line ("Sessions done") reaches
the terminal, then quits it with ctrl+q. This counts everything a user waits for:
the interpreter, the imports, the database's schema check, the roster query and the
first paint. The standard library's `pty` does the terminal (pexpect is only a test
dependency).
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
from dataclasses import asdict, dataclass

from study.bench.startup import study_command
from study.errors import StudyInputError

MARKER = b"Sessions done"
TARGET_S = 1.5
"""The issue's target: the overview within 1.5 s of starting."""


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
    target_s: float = TARGET_S

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def time_to_overview(db_url: str, timeout_s: float = 60.0) -> tuple[float, float]:
    """(seconds from starting `study tui --db db_url` to the overview on its terminal,
    CPU seconds of the whole run)."""
    cpu0 = _children_cpu_s()
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    env = {**os.environ, "TERM": "xterm-256color"}
    start = time.monotonic()
    proc = subprocess.Popen(
        [*study_command(), "tui", "--db", db_url],
        stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True,
    )  # fmt: skip
    os.close(slave)
    seen = b""
    try:
        while MARKER not in seen:
            if time.monotonic() - start > timeout_s:
                raise StudyInputError(
                    f"`study tui --db {db_url}` showed no overview in {timeout_s:.0f} s; "
                    "expected a study database"
                )
            ready, _, _ = select.select([master], [], [], 0.05)
            if ready:
                try:
                    seen = seen[-64:] + os.read(master, 65536)
                except OSError:  # the app ended (its terminal closed)
                    raise StudyInputError(
                        f"`study tui --db {db_url}` ended before showing the overview"
                    ) from None
        elapsed = time.monotonic() - start
        os.write(master, b"\x11")  # ctrl+q
        _drain_until_exit(proc, master)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
    return elapsed, _children_cpu_s() - cpu0


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


def bench_tui(
    db_url: str, app_seconds: Callable[[str], float], runs: int = 5
) -> TuiBenchResult:
    """`runs` starts of `study tui` on a terminal, and `runs` of the app's own part
    (`app_seconds(db_url)`: make_app to the overview, `study.tui.probes`)."""
    from db.migrate import open_database
    from study.protocol.roster import schedule

    engine = open_database(db_url, create=False)
    try:
        participants = len(schedule(engine)["participants"])
    finally:
        engine.dispose()
    runs_s = [time_to_overview(db_url) for _ in range(runs)]
    seconds = [wall for wall, _ in runs_s]
    return TuiBenchResult(
        seconds, statistics.median(seconds), participants, [cpu for _, cpu in runs_s],
        [app_seconds(db_url) for _ in range(runs)],
    )  # fmt: skip
