"""A scripted run shows it is alive: `study demo --out d > log 2>&1` writes a progress
line at least every ten seconds (a bar or a spinner draws nothing on a file)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

ELAPSED = re.compile(r"; (?:(\d+) min )?(\d+) s elapsed")
TOTAL = re.compile(r"\((?:(\d+) min )?(\d+) s\)$")


def elapsed_s(line: str) -> int | None:
    """The seconds a progress line says have passed (`1 min 05 s elapsed` -> 65)."""
    found = ELAPSED.search(line)
    if found is None:
        return None
    return int(found.group(1) or 0) * 60 + int(found.group(2))


def test_elapsed_is_read_back() -> None:
    assert elapsed_s("study demo: analysis and figures; 1 min 05 s elapsed") == 65
    assert elapsed_s("study demo: sessions: 2/6 participants (P002); 10 s elapsed") == 10
    assert elapsed_s("SIMULATED demo study ...") is None


def test_a_demo_into_a_log_file_writes_a_line_every_ten_seconds(tmp_path: Path) -> None:
    study = shutil.which("study", path=str(Path(sys.executable).parent))
    assert study
    log = tmp_path / "log"
    start = time.monotonic()
    with log.open("w") as out:
        result = subprocess.run(
            [study, "demo", "--quick", "--out", str(tmp_path / "d")],
            stdout=out,
            stderr=subprocess.STDOUT,
            env={**os.environ, "MPLBACKEND": "Agg"},
            timeout=600,
            cwd=tmp_path,
        )
    took_s = time.monotonic() - start
    lines = log.read_text().splitlines()
    assert result.returncode == 0, lines[-5:]
    assert lines[-1].startswith("SIMULATED demo study"), lines[-1]
    progress = [line for line in lines if line.startswith("study demo: ")]
    seconds = [s for s in map(elapsed_s, progress) if s is not None]
    assert len(seconds) == len(progress)
    # a line at 10 s, 20 s, ... for as long as the demo ran (rounded to whole seconds)
    assert len(seconds) >= int(took_s // 10) - 1
    # from the start to each line: never more than ten seconds of silence (plus a second
    # of rounding)
    marks = [0, *seconds]
    gaps = [b - a for a, b in zip(marks, seconds, strict=False)]
    assert all(gap <= 11 for gap in gaps), gaps
    assert all(gap >= 9 for gap in gaps), gaps  # and not more often
    # and from the last line to the end, by the demo's own clock (its last line's time)
    total = TOTAL.search(lines[-1])
    assert total is not None, lines[-1]
    total_s = int(total.group(1) or 0) * 60 + int(total.group(2))
    assert total_s - marks[-1] <= 11, (total_s, seconds)
    assert total_s <= took_s + 1
