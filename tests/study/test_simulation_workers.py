"""The participant fit's simulation workers end when the process that started them is
killed: they share their task queue's pipe, so none ever reads an end of file from it,
and before they watched their parent they waited on it for good (seen: two workers of
a killed `participants_probes` bench alive an hour later)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

SCRIPT = """
import sys, time
from study.analysis.participant_fit.simulate import _POOL, worker_pool

with worker_pool("lcca", 2):
    pool = _POOL.get()[2]
    for f in [pool.submit(int) for _ in range(4)]:
        f.result()
    print(" ".join(str(pid) for pid in pool._processes), flush=True)
    time.sleep(120)
"""


def _alive(pid: int) -> bool:
    """A process that runs (a zombie, ended but not yet reaped by its new parent, is not)."""
    stat = Path(f"/proc/{pid}/stat")
    try:
        state = stat.read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False
    return state != "Z"


def test_workers_end_when_their_parent_is_killed() -> None:
    parent = subprocess.Popen(
        [sys.executable, "-c", SCRIPT], stdout=subprocess.PIPE, text=True, env=os.environ.copy()
    )
    try:
        assert parent.stdout is not None
        workers = [int(p) for p in parent.stdout.readline().split()]
        assert len(workers) == 2
        assert all(_alive(p) for p in workers)
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    deadline = time.monotonic() + 20
    while any(_alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [p for p in workers if _alive(p)]
    for p in left:  # do not leave them behind if the check fails
        os.kill(p, signal.SIGKILL)
    assert left == []
