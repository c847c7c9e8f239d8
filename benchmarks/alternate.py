"""What the side-by-side benches share: a child process timed by its own CPU time, the
median of each figure over the alternating rounds, and the report written and shown.

The benches run two things in turn (two checkouts, or this tool and R) on a shared
machine whose speed drifts, so each round alternates the order and the report keeps the
medians; CPU time of the child (rusage) is what other jobs on the machine disturb least.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import time
from pathlib import Path
from typing import Any


def timed(*args: Any, **kwargs: Any) -> tuple[subprocess.CompletedProcess, dict[str, float]]:
    """`subprocess.run(*args, **kwargs)`, its wall and CPU seconds (the child's) and the
    machine's 1-minute load average as it started (the other jobs sharing the cores)."""
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(*args, **kwargs)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return done, {"wall_s": wall, "cpu_s": cpu, "load_avg_1min": load}


def medians(runs: dict[str, list[dict[str, float]]]) -> dict[str, dict[str, float]]:
    """Per label, the median of each figure over its rounds."""
    return {
        label: {k: statistics.median(run[k] for run in rs) for k in rs[0]}
        for label, rs in runs.items()
    }


def write_report(report: dict[str, Any], out: Path | None) -> None:
    """The report as JSON to `out` (if given) and to stdout."""
    text = json.dumps(report, indent=2) + "\n"
    if out:
        out.write_text(text)
    print(text)
