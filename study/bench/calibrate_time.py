"""`study bench calibrate --time`: how long `study calibrate` takes on a 4-minute recording.

Each recording is written to a temporary folder and calibrated by `study calibrate` in
a fresh process (as a user runs it: the imports, reading the file, the loop, the
figures and the report), `repeats` times, one recording after the other. Per run: the
wall-clock seconds, the CPU seconds of the process (user + system,
`resource.getrusage(RUSAGE_CHILDREN)`: every thread of it), the 1-minute load average
at its start, and what the run found (effects added, verdict), so that a faster run
that finds something else shows.

The recordings: SIMULATED follower recordings (`synthetic.follower_recording`, the
effects at the JND's size), 240 s at 200 Hz (48,000 rows): clean, one effect
(`stribeck`), three (`stribeck`, `hysteresis`, `drift`) and a torque ripple
(`position_periodic`, whose period search reads the residual's periodogram); and the
EMPS drive's measured recording (24.8 s at 1 kHz, `--model rigid-axis`) where its file
is found.

On a machine shared with other work the wall clock is the CPU time stretched by the
share of the cores the run gets; the CPU time is what a free core would take. The
target (60 s for a 4-minute recording) is read against both.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from study.bench.calibrate_open import EMPS_FILE
from teleop_core.calibration.synthetic import JND_N, follower_recording
from teleop_core.progress import Progress, no_progress

TARGET_S = 60.0
"""The target: a 4-minute recording calibrated in at most this many seconds."""
COMMAND = (
    "study calibrate REC --json REC.json --predictions REC.pred.csv --out REC.out "
    "(default: --model follower, --held-out 0.25, --max-effects 4, every family; "
    "--model rigid-axis for EMPS)"
)


@dataclass(frozen=True)
class CalibrateTimeConfig:
    duration_s: float = 240.0
    """Length of each simulated recording, s (the target's 4 minutes)."""
    rate_hz: float = 200.0
    """Its sampling rate, Hz."""
    seed: int = 0
    """Seed of the simulated recordings."""
    repeats: int = 2
    """Runs of each recording."""
    recordings: dict[str, tuple[str, ...]] = field(
        default_factory=lambda: {
            "clean": (),
            "stribeck": ("stribeck",),
            "three": ("stribeck", "hysteresis", "drift"),
            "ripple": ("position_periodic",),
        }
    )
    """Simulated recordings by name: the effects each carries."""
    emps: bool = True
    """Whether the EMPS drive's recording is timed too (where its file is found)."""

    @classmethod
    def quick(cls) -> CalibrateTimeConfig:
        return cls(duration_s=60.0, rate_hz=100.0, repeats=1, emps=False)


def timed_calibrate(recording: Path, out: Path, model: str = "follower") -> dict[str, Any]:
    """`study calibrate` on `recording` in a fresh process: wall and CPU seconds, the load
    average at its start, and the report's effects and verdict."""
    report = out / f"{recording.stem}.json"
    argv = [
        *(sys.executable, "-m", "study.cli", "calibrate", str(recording)),
        *("--model", model, "--json", str(report)),
        *("--predictions", str(out / f"{recording.stem}.pred.csv")),
        *("--out", str(out / f"{recording.stem}.out")),
    ]
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"study calibrate {recording.name} failed:\n{done.stderr[-2000:]}")
    found = json.loads(report.read_text())
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), 2),
        "cpu_user_s": round(after.ru_utime - before.ru_utime, 2),
        "load_average_1min_at_start": round(load, 2),
        "effects_added": [e["family"] for e in found["effects_added"]],
        "discovered_terms": [e["term"] for e in found["discovered_terms"]],
        "verdict": found["verdict"],
        "rmse_after": found["rmse_after"],
    }


def run_calibrate_time_bench(
    config: CalibrateTimeConfig, out_dir: Path, progress: Progress = no_progress
) -> dict[str, Any]:
    """Time `study calibrate` on each recording of `config`; writes calibrate_time.md
    into `out_dir` and returns the JSON report."""
    runs: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="calibrate-time-") as tmp:
        folder = Path(tmp)
        files: list[tuple[str, Path, str]] = []
        for name, effects in config.recordings.items():
            rec, _ = follower_recording(
                config.duration_s, effects, rate_hz=config.rate_hz, seed=config.seed, size_n=JND_N
            )
            path = folder / f"{name}.csv"
            rec.to_csv(path)
            files.append((name, path, "follower"))
        if config.emps and EMPS_FILE.is_file():
            files.append(("emps", EMPS_FILE, "rigid-axis"))
        total = len(files) * config.repeats
        for repeat in range(1, config.repeats + 1):
            for name, path, model in files:
                progress(f"study calibrate {name}", len(runs), total)
                run = timed_calibrate(path, folder, model)
                runs.append({"recording": name, "repeat": repeat, **run})
    report = {
        "data": (
            f"SIMULATED follower recordings (teleop_core.calibration.synthetic."
            f"follower_recording, seed {config.seed}, size JND_N), {config.duration_s:g} s "
            f"at {config.rate_hz:g} Hz ({round(config.duration_s * config.rate_hz)} rows) "
            "each"
            + ("; EMPS: the drive's measured recording (24.8 s at 1 kHz)" if config.emps else "")
        ),
        "recordings": {name: list(effects) for name, effects in config.recordings.items()},
        "command": COMMAND + ", each in a fresh process; wall clock and CPU (user + system) "
        "of that process",
        "bench": "study bench calibrate --time --json benchmarks/results/calibrate_time.json",
        "machine": f"{os.cpu_count()} cores, shared with other work (load average per run)",
        "target_s": TARGET_S,
        "runs": runs,
        "summary": _summary(runs),
        "note": "wall_s is wall clock on the machine as loaded; cpu_s is the CPU time the "
        "command used (user + system, all threads), what a free core would take",
    }
    (out_dir / "calibrate_time.md").write_text(markdown(report))
    return report


def _summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    simulated = [r for r in runs if r["recording"] != "emps"]
    return {
        "max_cpu_s": max((r["cpu_s"] for r in simulated), default=float("nan")),
        "max_wall_s": max((r["wall_s"] for r in simulated), default=float("nan")),
        "load_average_range": [
            min((r["load_average_1min_at_start"] for r in runs), default=float("nan")),
            max((r["load_average_1min_at_start"] for r in runs), default=float("nan")),
        ],
        "within_target_cpu": all(r["cpu_s"] <= TARGET_S for r in simulated),
        "within_target_wall": all(r["wall_s"] <= TARGET_S for r in simulated),
    }


def markdown(report: dict[str, Any]) -> str:
    """The runs as a Markdown table."""
    lines = [
        "# `study calibrate`: time per recording",
        "",
        report["data"] + ".",
        "",
        "| recording | run | CPU s | wall s | load average | effects added | verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in report["runs"]:
        added = ", ".join(r["effects_added"] + r["discovered_terms"]) or "none"
        lines.append(
            f"| {r['recording']} | {r['repeat']} | {r['cpu_s']:.1f} | {r['wall_s']:.1f} | "
            f"{r['load_average_1min_at_start']:.1f} | {added} | {r['verdict']} |"
        )
    s = report["summary"]
    lines += [
        "",
        f"Slowest simulated recording: {s['max_cpu_s']:.1f} s CPU, "
        f"{s['max_wall_s']:.1f} s wall (target {report['target_s']:g} s).",
        "",
    ]
    return "\n".join(lines)
