"""`study bench startup`: what a user waits for from a cold process.

Each figure but the writer's is the median of `runs` fresh subprocesses, after one
warm-up run that is not counted (it leaves the loop kernel compiled ahead of time in
the kernel cache, `teleop_core/loop/aot.py`, as the first run after install does):

- `study simulate` of a 30 s LCCA trial (a novice, HV, seed 3, who does not reach the
  target within `--max-seconds 30`), start to exit, wall seconds;
- the TUI's run screen: in a fresh process, headless under a Textual pilot, from the
  overview showing to the run screen's "preparing the simulation" ending
  (`RunPane.simulation.ready()` returned: estimator loaded, loop kernel ready), the run
  screen being opened as soon as the app lets it;
- `study analyze` of a study database, start to exit, wall seconds;
- the sample writer (`db.samples.SampleWriter`, through `study bench db`'s path)
  against a plain `sqlite3` multi-row INSERT of the same rows, a row per sample, into
  a table of the row-per-sample layout the study database had up to revision 0004
  (`samples`: trial_id, seq and 12 columns, created in the same scratch file), with
  the same settings (WAL, synchronous=FULL, a commit per 1,000 rows), measured in
  the same run, alternately, as rows/s and their ratio; and against the same INSERT
  with `PRAGMA foreign_keys=ON`, which every connection to a study database has (the
  writer's rows pay a lookup of their trial each; the plain reference does not);
- `study demo` (the whole 36-participant study, figures included, two worker processes),
  start to exit, wall seconds, `demo_runs` times after its own warm-up (the OS's file
  cache; the loop kernel is compiled by then, as after the first run after install).

This module imports only the standard library at its top: the run-screen probe
imports it in the subprocess it times.
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

from study.errors import StudyInputError
from teleop_core.progress import Progress, no_progress

SIMULATE_ARGS = (
    "simulate",
    "--task",
    "lcca",
    "--group",
    "novice",
    "--condition",
    "HV",
    "--seed",
    "3",
    "--max-seconds",
    "30",
)
"""A trial that runs its full 30 s (seed 3 does not reach the target in time)."""
TARGETS_S = {"simulate": 1.0, "run_screen": 1.0, "analyze": 2.0, "demo": 30.0}
"""The targets, s; the writer's is `WRITER_TARGET_RATIO`."""
WRITER_TARGET_RATIO = 0.9
_REFERENCE_ROWS_PER_COMMIT = 1000


@dataclass(frozen=True)
class Timing:
    """One figure timed over fresh processes."""

    seconds: list[float]
    """Wall time of each counted run, s."""
    median_s: float
    target_s: float

    @classmethod
    def of(cls, seconds: list[float], target_s: float) -> Timing:
        return cls(seconds, statistics.median(seconds), target_s)


@dataclass(frozen=True)
class WriterRatio:
    rows: int
    writer_rows_per_s: list[float]
    """`SampleWriter`, each run."""
    sqlite3_rows_per_s: list[float]
    """The plain sqlite3 multi-row INSERT, each run."""
    sqlite3_foreign_keys_rows_per_s: list[float]
    """The same with `PRAGMA foreign_keys=ON`, as the study database's connections have
    (each sample's trial_id is then looked up in `trials`), each run."""
    ratio: float
    """Median writer rows/s over median plain sqlite3 rows/s (the target)."""
    ratio_foreign_keys: float
    """Median writer rows/s over median sqlite3 rows/s with foreign keys checked."""
    target_ratio: float = WRITER_TARGET_RATIO


@dataclass(frozen=True)
class StartupBenchResult:
    runs: int
    simulate: Timing
    simulate_trial_s: float
    """Trial time of the simulated trial, s (from its summary)."""
    run_screen: Timing
    analyze: Timing
    analyze_db: str
    writer: WriterRatio
    demo: Timing | None = None
    """`study demo` start to exit (None: not run, `demo_runs` 0)."""
    load_average: list[float] = field(default_factory=lambda: list(os.getloadavg()))
    """1, 5 and 15 min load averages at the end of the run."""

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def study_command() -> list[str]:
    """How to start `study` in a subprocess: the console script next to this Python."""
    exe = shutil.which("study", path=str(Path(sys.executable).parent)) or shutil.which("study")
    if exe is None:
        return [sys.executable, "-c", "import sys; from study.cli import main; sys.exit(main())"]
    return [exe]


def _wall(args: list[str], timeout_s: float = 300.0) -> float:
    start = time.perf_counter()
    proc = subprocess.run(args, capture_output=True, text=True, timeout=timeout_s)
    seconds = time.perf_counter() - start
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise StudyInputError(f"`{' '.join(args[-12:])}` failed: {tail}")
    return seconds


def _timed(args: Callable[[int], list[str]], runs: int, target_s: float) -> Timing:
    _wall(args(0))  # warm-up: the kernel cache and the OS's file cache exist afterwards
    return Timing.of([_wall(args(k + 1)) for k in range(runs)], target_s)


def bench_simulate(tmp: Path, runs: int) -> tuple[Timing, float]:
    def args(k: int) -> list[str]:
        return [*study_command(), *SIMULATE_ARGS, "--out", str(tmp / f"sim{k}.csv")]

    timing = _timed(args, runs, TARGETS_S["simulate"])
    summary = json.loads((tmp / "sim1.json").read_text())
    return timing, float(summary["completion_time_s"])


def bench_analyze(db_url: str, tmp: Path, runs: int) -> Timing:
    def args(k: int) -> list[str]:
        return [*study_command(), "analyze", "--db", db_url, "--out", str(tmp / f"analysis{k}")]

    return _timed(args, runs, TARGETS_S["analyze"])


def bench_run_screen(db_url: str, runs: int) -> Timing:
    code = (
        "import sys; from study.tui.probes import print_run_screen_seconds; "
        "print_run_screen_seconds(sys.argv[1])"
    )

    def once() -> float:
        proc = subprocess.run(
            [sys.executable, "-c", code, db_url], capture_output=True, text=True, timeout=300
        )
        if proc.returncode != 0:
            tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
            raise StudyInputError(f"the run-screen probe failed: {tail}")
        return float(json.loads(proc.stdout.strip().splitlines()[-1])["seconds"])

    once()
    return Timing.of([once() for _ in range(runs)], TARGETS_S["run_screen"])


def bench_demo(tmp: Path, runs: int, extra: tuple[str, ...] = ()) -> Timing:
    """`study demo [extra]` into a new folder under `tmp` each time."""

    def args(k: int) -> list[str]:
        return [*study_command(), "demo", "--out", str(tmp / f"demo{k}"), *extra]

    return _timed(args, runs, TARGETS_S["demo"])


def _reference_insert(
    path: Path, trial_id: int, columns: dict, names: tuple[str, ...], foreign_keys: bool = False
) -> float:
    """Seconds for a plain sqlite3 multi-row INSERT of `columns` (numpy arrays, as the
    writer is handed them) into a row-per-sample `samples` table created in the SQLite
    file `path` (the layout up to revision 0004; the writer now stores chunks): WAL,
    synchronous=FULL, one statement and one commit per 1,000 rows, 14 columns; foreign
    keys checked if `foreign_keys`."""

    rows = len(columns["t_s"])
    conn = sqlite3.connect(path, isolation_level=None)
    try:
        conn.execute("PRAGMA journal_mode=WAL")
        conn.execute("PRAGMA synchronous=FULL")
        conn.execute(f"PRAGMA foreign_keys={'ON' if foreign_keys else 'OFF'}")
        kinds = {"trial_id": "INTEGER", "seq": "INTEGER", "branch": "TEXT"}
        typed = ", ".join(f"{name} {kinds.get(name, 'REAL')}" for name in names)
        conn.execute(
            f"CREATE TABLE samples ({typed}, PRIMARY KEY (trial_id, seq), "
            "FOREIGN KEY (trial_id) REFERENCES trials (id) ON DELETE CASCADE)"
        )
        head = f"INSERT INTO samples ({', '.join(names)}) VALUES "
        one = "(" + ", ".join("?" * len(names)) + ")"
        full = head + ", ".join([one] * _REFERENCE_ROWS_PER_COMMIT)
        start = time.perf_counter()
        values = {name: col.tolist() for name, col in columns.items()}
        nulls = [None] * _REFERENCE_ROWS_PER_COMMIT
        for lo in range(0, rows, _REFERENCE_ROWS_PER_COMMIT):
            hi = min(lo + _REFERENCE_ROWS_PER_COMMIT, rows)
            part = [
                [trial_id] * (hi - lo),
                range(lo, hi),
                *(values[name][lo:hi] if name in values else nulls for name in names[2:]),
            ]
            n = hi - lo
            sql = full if n == _REFERENCE_ROWS_PER_COMMIT else head + ", ".join([one] * n)
            conn.execute("BEGIN")
            conn.execute(sql, list(itertools.chain.from_iterable(zip(*part, strict=False))))
            conn.execute("COMMIT")
        return time.perf_counter() - start
    finally:
        conn.close()


def bench_writer(rows: int, runs: int, rate_hz: float = 1000.0) -> WriterRatio:
    """The writer's rows/s and the plain sqlite3 reference's over the same rows, the two
    alternating, `runs` each (a fresh temporary SQLite file every time)."""
    # lazy: study.bench.db_write (with pyarrow, sqlalchemy, numpy) costs 0.4 s at start-up
    from study.bench.db_write import (
        bench_sample_write,
        bench_schema,
        scratch_database,
        scratch_trial,
        synthetic_columns,
    )

    names = ("trial_id", "seq", *bench_schema().names)  # the task's declared columns
    columns = synthetic_columns(rows, rate_hz, seed=0)  # bench_sample_write's rows
    writer: list[float] = []
    reference: dict[bool, list[float]] = {False: [], True: []}
    for _ in range(runs):
        writer.append(bench_sample_write(None, rows=rows, rate_hz=rate_hz).rows_per_s)
        for foreign_keys, rates in reference.items():
            with scratch_database(None) as engine:
                trial_id = scratch_trial(engine)
                path = Path(str(engine.url.database))
                engine.dispose()
                seconds = _reference_insert(path, trial_id, columns, names, foreign_keys)
                rates.append(rows / seconds)
    w = statistics.median(writer)
    return WriterRatio(
        rows,
        writer,
        reference[False],
        reference[True],
        w / statistics.median(reference[False]),
        w / statistics.median(reference[True]),
    )


def bench_startup(
    runs: int,
    db_url: str | None = None,
    rows: int = 1_000_000,
    progress: Progress = no_progress,
    demo_runs: int = 1,
) -> StartupBenchResult:
    """Every figure of the module's docstring. Without `db_url`, `study analyze` and the
    run screen work on a quick demo study (6 participants) built first. `demo_runs` 0
    leaves `study demo` out."""
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        analyze_db = db_url or "a quick demo study (study demo --quick --seed 1)"
        if db_url is None:
            from study.protocol.demo import run_demo

            progress("building a quick demo study (6 participants)")
            db_url = str(tmp / "demo.db")
            run_demo(db_url, seed=1, progress=progress, quick=True)
        progress(f"study simulate, {runs} + 1 fresh processes")
        simulate, trial_s = bench_simulate(tmp, runs)
        progress(f"the run screen, {runs} + 1 fresh processes")
        run_screen = bench_run_screen(db_url, runs)
        progress(f"study analyze, {runs} + 1 fresh processes")
        analyze = bench_analyze(db_url, tmp, runs)
        progress(f"the sample writer and plain sqlite3, {rows:,} rows, {runs} runs each")
        writer = bench_writer(rows, runs)
        demo = None
        if demo_runs:
            progress(f"study demo, {demo_runs} + 1 fresh processes")
            demo = bench_demo(tmp, demo_runs)
    return StartupBenchResult(
        runs, simulate, trial_s, run_screen, analyze, analyze_db, writer, demo
    )
