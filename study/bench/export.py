"""`study bench export`: time and peak memory of `study export --samples` on a large study.

The benchmark builds a scratch study database (a temporary SQLite file, or a private
schema on a PostgreSQL server, dropped afterwards: `study.bench.db_write.
scratch_database`), with the template design, `participants` x 8 completed trials
and `samples` samples in all, written at 1 kHz through `db.samples.SampleWriter`, the
session runner's writer. The samples are synthetic (seeded random values in every
column, a `branch` name per sample): they measure the storage and the export, not a
participant; each trial's measures (completion time, peak proximal and distal force)
are computed from its samples, so that the analysis and Fig. 12 have something to
show. It then runs the real command, `study export --samples --format F`, in a child
process per format and reads the child's wall time, CPU time (user + system, less
sensitive than the wall time to the other jobs of a shared machine) and peak resident
memory (`os.wait4`'s `ru_maxrss`), and the bytes per sample of the database and of the
file. Then the readers of samples other than the export, each in a child process:
`study figures --format png`, and the terminal app's analysis screen (headless: the
overview, the analysis, the figures' export; `study.tui.probes`).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from sqlalchemy import URL, Engine, text

from db.engine import is_sqlite, make_session_factory
from db.models import Participant, Trial, TrialMeasure
from db.samples import SampleWriter
from study.bench.db_write import scratch_database
from study.protocol.design import TEMPLATE, parse_design
from study.protocol.roster import create_study
from study.protocol.tasks import get_task
from teleop_core.progress import Progress, no_progress

TRIALS_PER_PARTICIPANT = 8
"""Template design with two tasks' worth of blocks: 2 conditions x 4 trials."""
RATE_HZ = 1000.0


@dataclass(frozen=True)
class ExportRun:
    fmt: str
    seconds: float
    samples_per_s: float
    peak_rss_mb: float
    file_bytes_per_sample: float
    cpu_seconds: float = math.nan
    """User + system CPU time of the export's process (all its threads), s."""
    load_average: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    """`os.getloadavg()` when the run ended (1, 5, 15 minutes)."""


@dataclass(frozen=True)
class ExportBenchResult:
    backend: str
    samples: int
    trials: int
    build_seconds: float
    write_rows_per_s: float
    db_bytes_per_sample: float
    runs: list[ExportRun] = field(default_factory=list)
    figures_seconds: float = math.nan
    figures_peak_mb: float = math.nan
    """Peak resident memory of `study figures --format png` on the study, MB."""
    tui_seconds: float = math.nan
    tui_peak_mb: float = math.nan
    """Peak resident memory of the app's analysis screen (analysis, then figures), MB."""
    workers: int = 0
    """Reader threads the export used (`study export --jobs`; 0: its default)."""

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def _columns(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    t = np.arange(n) / RATE_HZ
    names = np.array(["DAo", "arch", "AAo", "LSA", "LCCA", "BCT"], dtype=object)
    return {
        "t_s": t,
        "insertion_m": 0.002 * t,
        "rotation_rad": rng.normal(0, 3, n),
        "tip_x_m": rng.normal(0, 0.05, n),
        "tip_y_m": rng.normal(0, 0.05, n),
        "tip_z_m": rng.normal(0, 0.05, n),
        "branch": names[rng.integers(0, len(names), n)],
        "reference_force_n": np.abs(rng.normal(0.5, 0.2, n)),
        "proximal_force_n": np.abs(rng.normal(0.5, 0.2, n)),
        "distal_force_n": np.abs(rng.normal(0.1, 0.05, n)),
        "dial_angle_rad": rng.normal(0.0, 0.3, n),
        "dial_torque_n_m": rng.normal(0.0, 0.01, n),
    }


def build_study(
    engine: Engine,
    samples: int,
    participants: int,
    *,
    seed: int = 0,
    progress: Progress = no_progress,
) -> tuple[int, float]:
    """Write the benchmark study; returns (trials, seconds spent in the sample writer)."""
    design = parse_design(TEMPLATE)
    study = create_study(engine, design, TEMPLATE)
    n_trials = participants * TRIALS_PER_PARTICIPANT
    with make_session_factory(engine).begin() as session:
        trials = []
        for p in range(participants):
            person = Participant(
                study_id=study.id,
                code=f"P{p + 1:03d}",
                group="novice",
                condition_order=list(design.conditions),
            )
            for k in range(TRIALS_PER_PARTICIPANT):
                block, index = divmod(k, TRIALS_PER_PARTICIPANT // 2)
                trials.append(
                    Trial(
                        participant=person,
                        task="lcca",
                        condition=design.conditions[block],
                        block_index=block,
                        trial_index=index,
                        status="completed",
                        driver="simulated",
                    )
                )
        session.add_all(trials)
        session.flush()
        ids = [t.id for t in trials]
    rng = np.random.default_rng(seed)
    per_trial = np.full(n_trials, samples // n_trials)
    per_trial[: samples % n_trials] += 1
    writing = 0.0
    written = 0
    measures: dict[int, dict[str, float]] = {}
    schema = get_task("lcca").sample_schema()  # the trials' task's, as a session writes
    for trial_id, n in zip(ids, per_trial, strict=True):
        columns = _columns(rng, int(n))
        start = time.perf_counter()
        with SampleWriter(engine, trial_id, schema=schema) as writer:
            for lo in range(0, int(n), int(RATE_HZ)):
                writer.extend({k: v[lo : lo + int(RATE_HZ)] for k, v in columns.items()})
        writing += time.perf_counter() - start
        measures[trial_id] = {
            "completion_time_s": float(columns["t_s"][-1]),
            "peak_proximal_force_n": float(np.max(columns["proximal_force_n"])),
            "peak_distal_force_n": float(np.max(columns["distal_force_n"])),
        }
        written += int(n)
        progress("writing the study's samples", written, samples)
    _store_measures(engine, measures)
    return n_trials, writing


def _store_measures(engine: Engine, measures: dict[int, dict[str, float]]) -> None:
    """Each trial's completion time, success and peak forces, as the runner stores them."""
    with make_session_factory(engine).begin() as session:
        for trial in session.query(Trial).filter(Trial.id.in_(list(measures))):
            values = measures[trial.id]
            trial.completion_time_s = values["completion_time_s"]
            trial.success = True
        session.add_all(
            TrialMeasure(trial_id=trial_id, name=name, value=value)
            for trial_id, values in measures.items()
            for name, value in values.items()
            if name != "completion_time_s"
        )


def _db_bytes(engine: Engine) -> int:
    with engine.connect() as conn:
        if is_sqlite(conn):
            conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
            return Path(str(engine.url.database)).stat().st_size
        return int(conn.scalar(text("SELECT pg_total_relation_size('sample_chunks')")))


@dataclass(frozen=True)
class _Child:
    seconds: float
    cpu_seconds: float
    peak_mb: float
    stdout: str


def _run_child(cmd: list[str], what: str) -> _Child:
    """Run `cmd`; its wall time, CPU time and peak resident memory (`os.wait4`)."""
    start = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err)
        # read while it runs (a full pipe would block it), then reap it with its usage
        out = child.stdout.read() if child.stdout else b""
        _, status, usage = os.wait4(child.pid, 0)
        seconds = time.perf_counter() - start
        child.returncode = os.waitstatus_to_exitcode(status)
        if child.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"{what} failed ({child.returncode}): {err.read().decode().strip()}")
    cpu = usage.ru_utime + usage.ru_stime
    return _Child(seconds, cpu, usage.ru_maxrss / 1024, out.decode())


def run_export(
    url: str, fmt: str, out_dir: Path, samples: int, workers: int | None = None
) -> ExportRun:
    """`study export --samples` in a child process: wall and CPU time, peak memory."""
    cmd = [
        sys.executable,
        "-m",
        "study.cli",
        "export",
        "--samples",
        "--format",
        fmt,
        "--out",
        str(out_dir),
        "--db",
        url,
    ]
    if workers is not None:
        cmd += ["--jobs", str(workers)]
    run = _run_child(cmd, "study export")
    size = (out_dir / f"samples.{fmt}").stat().st_size
    return ExportRun(
        fmt,
        run.seconds,
        samples / run.seconds,
        run.peak_mb,
        size / samples,
        run.cpu_seconds,
        os.getloadavg(),
    )


def run_figures(url: str, out_dir: Path) -> _Child:
    """`study figures --format png` in a child process."""
    cmd = [
        sys.executable,
        "-m",
        "study.cli",
        "figures",
        "--format",
        "png",
        "--out",
        str(out_dir),
        "--db",
        url,
    ]
    return _run_child(cmd, "study figures")


def run_tui_analysis(url: str, out_dir: Path) -> _Child:
    """The app's analysis screen (analysis, then the figures) in a child process."""
    code = (
        "import sys; from study.tui.probes import print_analysis_figures_peak; "
        "print_analysis_figures_peak(sys.argv[1], sys.argv[2])"
    )
    run = _run_child([sys.executable, "-c", code, url, str(out_dir)], "the analysis screen")
    if not json.loads(run.stdout.strip().splitlines()[-1])["files"]:
        raise RuntimeError("the analysis screen wrote no figure")
    return run


def bench_export(
    db: str | URL | None = None,
    *,
    samples: int = 10_000_000,
    participants: int = 360,
    formats: tuple[str, ...] = ("parquet", "csv"),
    workers: int | None = None,
    progress: Progress = no_progress,
) -> ExportBenchResult:
    """Build the study, export it once per format (files in a temporary folder), then
    draw its figures with `study figures` and with the app's analysis screen."""
    with scratch_database(db) as engine:
        start = time.perf_counter()
        trials, writing = build_study(engine, samples, participants, progress=progress)
        build = time.perf_counter() - start
        db_bytes = _db_bytes(engine)
        url = engine.url.render_as_string(hide_password=False)
        runs = []
        with tempfile.TemporaryDirectory() as tmp:
            for fmt in formats:
                runs.append(run_export(url, fmt, Path(tmp) / fmt, samples, workers))
            figures = run_figures(url, Path(tmp) / "figures")
            tui = run_tui_analysis(url, Path(tmp) / "tui-figures")
        return ExportBenchResult(
            backend=engine.dialect.name,
            samples=samples,
            trials=trials,
            build_seconds=build,
            write_rows_per_s=samples / writing,
            db_bytes_per_sample=db_bytes / samples,
            runs=runs,
            figures_seconds=figures.seconds,
            figures_peak_mb=figures.peak_mb,
            tui_seconds=tui.seconds,
            tui_peak_mb=tui.peak_mb,
            workers=workers or 0,
        )
