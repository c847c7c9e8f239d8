"""The trial's clock on the LSL clock.

The session runner times a trial on `time.monotonic()` (`study.protocol.observer`);
liblsl stamps samples with its `local_clock()`. Both are the system's monotonic clock
on Linux, but not everywhere, so the offset between them is measured (the smallest of
a few back-to-back readings) rather than assumed.
"""

from __future__ import annotations

import time
from types import ModuleType


def monotonic_to_lsl(pylsl: ModuleType, probes: int = 20) -> float:
    """`local_clock() - time.monotonic()`, s: add it to a monotonic time to get LSL time."""
    best_width, offset = float("inf"), 0.0
    for _ in range(max(probes, 1)):
        a = time.monotonic()
        lsl = pylsl.local_clock()
        b = time.monotonic()
        if b - a < best_width:
            best_width, offset = b - a, lsl - (a + b) / 2
    return offset
