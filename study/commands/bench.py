"""`study bench ...`: measured figures for the README's Performance section."""

from __future__ import annotations

import json
import statistics
from dataclasses import replace
from pathlib import Path

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

from study.commands.base import StudyGroup
from study.errors import StudyInputError

_json_option = click.option(
    "--json",
    "json_path",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write every table as JSON here.",
)
_out_option = click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for the Markdown tables, the figures and any data files.",
)


def _check_json_folder(json_path: Path) -> None:
    if not json_path.parent.is_dir():
        raise StudyInputError(f"folder {json_path.parent} for {json_path.name} does not exist")


@click.group("bench", cls=StudyGroup)
def bench() -> None:
    """Benchmarks: speed figures measured on this machine."""


@bench.command("db")
@click.option(
    "--db",
    "db_url",
    metavar="URL",
    default=None,
    help="Benchmark against this server (PostgreSQL gets a private scratch schema) "
    "[default: a temporary SQLite file].",
)
@click.option("--rows", type=click.IntRange(min=1), default=1_000_000, show_default=True)
@click.option(
    "--rate-hz",
    type=click.FloatRange(min=0, min_open=True),
    default=1000.0,
    show_default=True,
    help="Sample rate of the synthetic trial; one chunk is committed per second of it.",
)
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
def bench_db(db_url: str | None, rows: int, rate_hz: float, json_path: Path | None) -> None:
    """Write one trial's samples through the session writer and report rows/s."""
    from study.bench.db_write import bench_sample_write

    with Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        transient=True,
        console=Console(stderr=True),
    ) as progress:
        task = progress.add_task("writing samples", total=rows)
        result = bench_sample_write(
            db_url, rows=rows, rate_hz=rate_hz, progress=lambda n: progress.advance(task, n)
        )
    click.echo(
        f"{result.backend}: {result.rows:,} rows in {result.chunks:,} committed chunks, "
        f"{result.seconds:.2f} s, {result.rows_per_s:,.0f} rows/s"
    )
    if json_path is not None:
        json_path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")


@bench.command("export")
@click.option(
    "--db",
    "db_url",
    metavar="URL",
    default=None,
    help="Benchmark against this server (PostgreSQL gets a private scratch schema) "
    "[default: a temporary SQLite file].",
)
@click.option("--samples", type=click.IntRange(min=1), default=10_000_000, show_default=True)
@click.option("--participants", type=click.IntRange(min=1), default=360, show_default=True)
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
def bench_export(db_url: str | None, samples: int, participants: int, json_path: Path | None) -> None:
    """Build a study of SAMPLES samples, export them to Parquet and CSV: time, memory, size."""
    from study.bench.export import bench_export as run_bench

    if json_path is not None:
        _check_json_folder(json_path)
    with Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        transient=True,
        console=Console(stderr=True),
    ) as progress:
        task = progress.add_task("writing the study's samples", total=samples)
        result = run_bench(
            db_url,
            samples=samples,
            participants=participants,
            progress=lambda n: progress.advance(task, n),
        )
    click.echo(
        f"{result.backend}: {result.samples:,} samples in {result.trials:,} trials, written at "
        f"{result.write_rows_per_s:,.0f} rows/s, {result.db_bytes_per_sample:.0f} bytes/sample "
        "in the database"
    )
    for run in result.runs:
        click.echo(
            f"  export --samples --format {run.fmt}: {run.seconds:.1f} s, "
            f"{run.samples_per_s:,.0f} samples/s, peak memory {run.peak_rss_mb:.0f} MB, "
            f"{run.file_bytes_per_sample:.1f} bytes/sample"
        )
    if json_path is not None:
        json_path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")


@bench.command("follower")
@_json_option
@_out_option
@click.option("--seed", type=int, default=0, show_default=True)
@click.option(
    "--quick",
    is_flag=True,
    help="Tiny data and 1-2 epochs: checks the pipeline in seconds, measures nothing.",
)
@click.option(
    "--only",
    type=click.Choice(["tables", "generalisation"]),
    default=None,
    help="Run one part: the paper's tables, or the estimator trained on the first 60 % of "
    "recordings with unmodelled effects and run on the rest [default: both].",
)
@click.option(
    "--generalisation-seeds",
    type=str,
    default=None,
    help="Comma-separated seeds of the generalisation part [default: 0,1,2,3,4].",
)
def bench_follower(
    json_path: Path,
    out_dir: Path,
    seed: int,
    quick: bool,
    only: str | None,
    generalisation_seeds: str | None,
) -> None:
    """Tables I-III and Fig. 8 of seed 000 on the simulated follower, and the estimator on
    recordings it never saw (about 30 min and several hours)."""
    from study.bench.follower import PARTS, FollowerBenchConfig, run_follower_bench

    _check_json_folder(json_path)
    config = FollowerBenchConfig.quick() if quick else FollowerBenchConfig()
    config = replace(config, seed=seed, parts=(only,) if only else PARTS)
    if generalisation_seeds is not None:
        try:
            seeds = tuple(int(s) for s in generalisation_seeds.split(","))
        except ValueError:
            raise StudyInputError(
                f"--generalisation-seeds {generalisation_seeds!r}; expected comma-separated "
                "integers such as 0,1,2"
            ) from None
        config = replace(config, generalisation=replace(config.generalisation, seeds=seeds))
    with Console(stderr=True).status("follower bench") as status:
        report = run_follower_bench(config, out_dir, progress=lambda msg: status.update(msg))
    json_path.write_text(json.dumps(report, indent=2) + "\n")
    click.echo((out_dir / "follower_bench.md").read_text())


@bench.command("master")
@_json_option
@_out_option
@click.option(
    "--estimator",
    "model_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Force estimator folder for the closed loop [default: the model shipped with "
    "haptic-study].",
)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--quick", is_flag=True, help="Short runs: checks the pipeline, measures little.")
def bench_master(
    json_path: Path, out_dir: Path, model_dir: Path | None, seed: int, quick: bool
) -> None:
    """Figs. 10-11 of seed 000 on the simulated dial, latency, and the loop's speed."""
    from study.bench.master import MasterBenchConfig, run_master_bench
    from study.protocol.default_estimator import load_estimator

    _check_json_folder(json_path)
    config = MasterBenchConfig.quick() if quick else MasterBenchConfig()
    config = replace(config, seed=seed)
    estimator = load_estimator(model_dir)
    with Console(stderr=True).status("master bench") as status:
        report = run_master_bench(
            config, out_dir, estimator=estimator, progress=lambda msg: status.update(msg)
        )
    json_path.write_text(json.dumps(report, indent=2) + "\n")
    click.echo((out_dir / "master_bench.md").read_text())


@bench.command("lcca")
@_json_option
@_out_option
@click.option(
    "--estimator",
    "model_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Force estimator folder [default: the model shipped with haptic-study].",
)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--quick", is_flag=True, help="Two participants per group, 60 s at most each.")
def bench_lcca(
    json_path: Path, out_dir: Path, model_dir: Path | None, seed: int, quick: bool
) -> None:
    """The paper's 20/8/8 user study with simulated participants, and its speed."""
    from study.bench.lcca import LccaBenchConfig, run_lcca_bench
    from study.protocol.default_estimator import load_estimator

    _check_json_folder(json_path)
    config = LccaBenchConfig.quick() if quick else LccaBenchConfig()
    config = replace(config, seed=seed)
    estimator = load_estimator(model_dir)
    with Console(stderr=True).status("simulated study") as status:
        report = run_lcca_bench(config, estimator, out_dir, progress=status.update)
    json_path.write_text(json.dumps(report, indent=2) + "\n")
    click.echo((out_dir / "lcca_bench.md").read_text())


@bench.command("campaign")
@click.option("--replicates", type=click.IntRange(min=1), default=8, show_default=True,
              help="Simulated studies in the campaign (units).")  # fmt: skip
@click.option("--group-size", type=click.IntRange(min=3), default=3, show_default=True,
              help="Participants per group in each simulated study.")  # fmt: skip
@click.option("--workers", type=click.IntRange(min=2), default=2, show_default=True)
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
def bench_campaign(replicates: int, group_size: int, workers: int, json_path: Path | None) -> None:
    """A campaign on 1 and on N Dask workers: units per hour, speed-up, overhead per unit."""
    from study.bench.campaign import run_campaign_bench

    if json_path is not None:
        _check_json_folder(json_path)
    with Console(stderr=True).status("campaign bench") as status:
        result = run_campaign_bench(replicates, group_size, workers, status.update)
    for run in result.runs:
        mean = sum(run.unit_seconds) / len(run.unit_seconds)
        click.echo(f"{run.workers} worker(s): {run.units} units in {run.wall_s:.1f} s, "
                   f"{run.units_per_hour:.0f} units/h, {mean:.2f} s per unit inside the "
                   f"worker, Dask overhead {100 * run.overhead:.1f} %")  # fmt: skip
    load = ", ".join(f"{x:.1f}" for x in result.load_average)
    click.echo(f"speed-up {workers} workers / 1: {result.speedup:.2f}x (target 1.8x for 2); "
               f"results identical: {'yes' if result.identical else 'NO'}; "
               f"{result.cpus} CPUs, load average {load} (simulated participants)")  # fmt: skip
    if json_path is not None:
        json_path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")


@bench.command("tui")
@click.option("--db", "db_url", metavar="URL", default=None,
              help="A study database, e.g. made by `study demo` [default: build the "
              "full 36-participant demo study in a temporary folder first, minutes].")  # fmt: skip
@click.option("--runs", type=click.IntRange(min=1), default=5, show_default=True)
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
def bench_tui(db_url: str | None, runs: int, json_path: Path | None) -> None:
    """Time from starting `study tui` to the overview on the terminal (target 1.5 s)."""
    import tempfile

    from study.bench.tui import bench_tui as run_bench
    from study.tui.probes import overview_seconds

    if json_path is not None:
        _check_json_folder(json_path)
    with tempfile.TemporaryDirectory() as tmp, Console(stderr=True).status("tui") as status:
        if db_url is None:
            from study.protocol.demo import run_demo

            db_url = str(Path(tmp) / "demo.db")
            status.update("building the full demo study (36 participants)")
            run_demo(db_url, seed=1, progress=status.update)
        status.update(f"starting `study tui` {runs} times")
        result = run_bench(db_url, overview_seconds, runs)
    click.echo(
        f"study tui, {result.participants} participants: overview after "
        f"{result.median_s:.2f} s (median of {runs}; "
        f"{', '.join(f'{s:.2f}' for s in result.seconds)} s); target <= {result.target_s} s; "
        f"CPU per run (start to exit) {', '.join(f'{s:.2f}' for s in result.cpu_seconds)} s; "
        f"the app's own part (make_app to overview, headless) "
        f"{', '.join(f'{s:.2f}' for s in result.app_seconds)} s"
    )
    if json_path is not None:
        json_path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")


@bench.command("startup")
@click.option("--runs", type=click.IntRange(min=1), default=5, show_default=True,
              help="Fresh processes per figure (after one warm-up each); the median counts.")
@click.option("--db", "db_url", metavar="URL", default=None,
              help="Study database for `study analyze` and the run screen, e.g. made by "
              "`study demo` [default: a quick 6-participant demo study built first].")
@click.option("--rows", type=click.IntRange(min=1), default=1_000_000, show_default=True,
              help="Samples written by the writer and by plain sqlite3, each run.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
def bench_startup(db_url: str | None, runs: int, rows: int, json_path: Path | None) -> None:
    """From a cold process (issue 21): simulate, the run screen, analyze, the writer."""
    from study.bench.startup import bench_startup as run_bench

    if json_path is not None:
        _check_json_folder(json_path)
    with Console(stderr=True).status("startup") as status:
        result = run_bench(runs, db_url, rows, progress=status.update)

    def line(name: str, t) -> str:  # type: ignore[no-untyped-def]
        each = ", ".join(f"{s:.2f}" for s in t.seconds)
        return f"{name}: {t.median_s:.2f} s (median of {runs}; {each}); target <= {t.target_s} s"

    w = result.writer
    trial = f"a {result.simulate_trial_s:.0f} s LCCA trial"
    click.echo(line(f"study simulate, {trial}", result.simulate))
    click.echo(line("run screen ready after the overview (headless)", result.run_screen))
    click.echo(line(f"study analyze of {result.analyze_db}", result.analyze))
    click.echo(
        f"sample writer {statistics.median(w.writer_rows_per_s):,.0f} rows/s, plain sqlite3 "
        f"{statistics.median(w.sqlite3_rows_per_s):,.0f} rows/s ({w.rows:,} rows): "
        f"{w.ratio:.2f}x; target >= {w.target_ratio}x; against sqlite3 with foreign keys "
        f"checked as the study database does "
        f"({statistics.median(w.sqlite3_foreign_keys_rows_per_s):,.0f} rows/s) "
        f"{w.ratio_foreign_keys:.2f}x"
    )
    load = ", ".join(f"{x:.2f}" for x in result.load_average)
    click.echo(f"load average {load}")
    if json_path is not None:
        json_path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")


@bench.command("calibrate")
@_json_option
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder for the Markdown table and a copy of the JSON [default: next to --json].",
)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--epochs", type=click.IntRange(min=1), default=None, help="GRU epochs [30].")
@click.option("--quick", is_flag=True, help="One-minute recordings at 100 Hz, 2 epochs.")
@click.option("--only-open", is_flag=True,
              help="Only measured data (EMPS), effects outside the families, clean seeds.")
def bench_calibrate(
    json_path: Path, out_dir: Path | None, seed: int, epochs: int | None, quick: bool,
    only_open: bool,
) -> None:  # fmt: skip
    """Calibration loop (issue 10): every family, the clean recording, speed, estimator."""
    from study.bench.calibrate import CalibrateBenchConfig, run_calibrate_bench

    _check_json_folder(json_path)
    config = CalibrateBenchConfig.quick() if quick else CalibrateBenchConfig()
    config = replace(config, seed=seed, **({"epochs": epochs} if epochs else {}))
    out_dir = out_dir or json_path.parent
    with Console(stderr=True).status("calibration bench") as status:
        report = run_calibrate_bench(config, out_dir, progress=status.update,
                                     only_open=only_open)  # fmt: skip
    json_path.write_text(json.dumps(report, indent=2) + "\n")
    click.echo((out_dir / "calibrate_bench.md").read_text())


@bench.command("notes")
@_json_option
@_out_option
@click.option(
    "--draws",
    type=click.IntRange(min=1),
    default=10,
    show_default=True,
    help="Seeded parameter draws per axis for the identification round trip.",
)
@click.option(
    "--trials",
    type=click.IntRange(min=1),
    default=4,
    show_default=True,
    help="Simulated NOTES trials per group and condition.",
)
@click.option("--seed", type=int, default=0, show_default=True)
def bench_notes(json_path: Path, out_dir: Path, draws: int, trials: int, seed: int) -> None:
    """Seed 001's NOTES device: bandwidth, settling, limits, identification round trip."""
    from study.bench.notes import NotesBenchConfig, run_notes_bench

    _check_json_folder(json_path)
    config = NotesBenchConfig(draws=draws, seed=seed, trials=trials)
    with Console(stderr=True).status("NOTES bench") as status:
        report = run_notes_bench(config, out_dir, progress=status.update)
    json_path.write_text(json.dumps(report, indent=2) + "\n")
    click.echo((out_dir / "notes_bench.md").read_text())
