"""`study bench ...`: measured figures for the README's Performance section.

Here the group and its speed benches (db, export, campaign, tui, startup); the paper's
tables and figures (follower, master, lcca, calibrate, notes) are in
`study.commands.bench_paper`.
"""

from __future__ import annotations

import statistics
from pathlib import Path

import click
from rich.console import Console

from study.analysis.participant_fit import WEAK_TRAITS
from study.commands.base import (
    SEED,
    StudyCommand,
    StudyGroup,
    bar_progress,
    check_parent_folder,
    positive_option,
    progress_bar,
    status_progress,
)
from study.commands.bench_paper import PAPER_BENCHES, write_json
from study.lsl.config import load_pylsl

_db_option = click.option(
    "--db",
    "db_url",
    metavar="URL",
    default=None,
    help="Benchmark against this server (PostgreSQL gets a private scratch schema) "
    "[default: a temporary SQLite file].",
)
_json_option = click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the figures as JSON to this file [default: print only].",
)


@click.group("bench", cls=StudyGroup)
def bench() -> None:
    """Benchmarks: speed figures measured on this machine.

    \b
    Example:
      study bench db --rows 100000
    """


for _command in PAPER_BENCHES:
    bench.add_command(_command)


@bench.command("db")
@_db_option
@click.option(
    "--rows",
    type=click.IntRange(min=1),
    default=1_000_000,
    show_default=True,
    help="Sample rows written and read back.",
)
@positive_option(
    "--rate-hz", 1000.0, "Sample rate of the synthetic trial; one chunk committed per second of it."
)
@_json_option
def bench_db(db_url: str | None, rows: int, rate_hz: float, json_path: Path | None) -> None:
    """Write one trial's samples through the session writer and report rows/s.

    \b
    Example:
      study bench db --rows 100000 --json db.json
    """
    # lazy: study.bench.db_write (with pyarrow, sqlalchemy, numpy) costs 0.4 s at start-up
    from study.bench.db_write import bench_sample_write

    with progress_bar() as progress:
        task = progress.add_task("writing samples", total=rows)
        told = bar_progress(progress, task, describe=False)
        result = bench_sample_write(db_url, rows=rows, rate_hz=rate_hz, progress=told)
    click.echo(
        f"{result.backend}: {result.rows:,} rows in {result.chunks:,} committed chunks, "
        f"{result.seconds:.2f} s, {result.rows_per_s:,.0f} rows/s"
    )
    write_json(json_path, result.to_dict())


@bench.command("export")
@_db_option
@click.option(
    "--samples",
    type=click.IntRange(min=1),
    default=10_000_000,
    show_default=True,
    help="Samples of the study that is exported.",
)
@click.option(
    "--participants",
    type=click.IntRange(min=1),
    default=360,
    show_default=True,
    help="Participants the samples are spread over.",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=None,
    help="Reader threads of the export [default: the export's own].",
)
@_json_option
def bench_export(
    db_url: str | None, samples: int, participants: int, jobs: int | None, json_path: Path | None
) -> None:
    """Build a study of SAMPLES samples, export them to Parquet and CSV (time, memory,
    size), then draw its figures with `study figures` and the app's analysis screen.

    \b
    Example:
      study bench export --samples 1000000 --participants 36
    """
    # lazy: study.bench.export (with pyarrow, sqlalchemy, numpy) costs 0.5 s at start-up
    from study.bench.export import bench_export as run_bench

    if json_path is not None:
        check_parent_folder(json_path)
    with progress_bar() as progress:
        task = progress.add_task("writing the study's samples", total=samples)
        result = run_bench(
            db_url,
            samples=samples,
            participants=participants,
            workers=jobs,
            progress=bar_progress(progress, task, describe=False),
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
            f"{run.file_bytes_per_sample:.1f} bytes/sample, {run.cpu_seconds:.1f} CPU-s, "
            f"load average {run.load_average[0]:.1f}"
        )
    click.echo(
        f"  study figures: {result.figures_seconds:.1f} s, peak memory "
        f"{result.figures_peak_mb:.0f} MB; analysis screen (analysis, figures): "
        f"{result.tui_seconds:.1f} s, peak memory {result.tui_peak_mb:.0f} MB"
    )
    write_json(json_path, result.to_dict())


@bench.command("campaign")
@click.option(
    "--replicates",
    type=click.IntRange(min=1),
    default=8,
    show_default=True,
    help="Simulated studies in the campaign (units).",
)
@click.option(
    "--group-size",
    type=click.IntRange(min=3),
    default=3,
    show_default=True,
    help="Participants per group in each simulated study.",
)
@click.option(
    "--workers",
    type=click.IntRange(min=2),
    default=2,
    show_default=True,
    help="Dask workers of the local cluster.",
)
@_json_option
def bench_campaign(replicates: int, group_size: int, workers: int, json_path: Path | None) -> None:
    """A campaign on 1 and on N Dask workers: units per hour, speed-up, overhead per unit.

    \b
    Example:
      study bench campaign --workers 2 --json campaign.json
    """
    # lazy: study.bench.campaign costs 9 ms at start-up
    from study.bench.campaign import run_campaign_bench

    if json_path is not None:
        check_parent_folder(json_path)
    with Console(stderr=True).status("campaign bench") as status:
        result = run_campaign_bench(replicates, group_size, workers, status_progress(status))
    for run in result.runs:
        mean = sum(run.unit_seconds) / len(run.unit_seconds)
        click.echo(
            f"{run.workers} worker(s): {run.units} units in {run.wall_s:.1f} s, "
            f"{run.units_per_hour:.0f} units/h, {mean:.2f} s per unit inside the "
            f"worker, Dask overhead {100 * run.overhead:.1f} %"
        )
    load = ", ".join(f"{x:.1f}" for x in result.load_average)
    click.echo(
        f"speed-up {workers} workers / 1: {result.speedup:.2f}x (target 1.8x for 2); "
        f"results identical: {'yes' if result.identical else 'NO'}; "
        f"{result.cpus} CPUs, load average {load} (simulated participants)"
    )
    write_json(json_path, result.to_dict())


@bench.command("tui")
@click.option(
    "--db",
    "db_url",
    metavar="URL",
    default=None,
    help="A study database, e.g. made by `study demo` [default: build the "
    "full 36-participant demo study in a temporary folder first, minutes].",
)
@click.option(
    "--runs",
    type=click.IntRange(min=1),
    default=5,
    show_default=True,
    help="Timed runs; the median is reported.",
)
@_json_option
def bench_tui(db_url: str | None, runs: int, json_path: Path | None) -> None:
    """Time from starting `study tui` to the overview on the terminal (target 1.5 s).

    \b
    Example:
      study bench tui --runs 3
    """
    # lazy: tempfile costs 3 ms at start-up
    import tempfile

    # lazy: study.bench.tui costs 16 ms at start-up
    from study.bench.tui import bench_tui as run_bench

    # lazy: study.tui.probes (with sqlalchemy, textual, rich) costs 0.5 s at start-up
    from study.tui.probes import overview_seconds

    if json_path is not None:
        check_parent_folder(json_path)
    with tempfile.TemporaryDirectory() as tmp, Console(stderr=True).status("tui") as status:
        if db_url is None:
            from study.protocol.demo import run_demo

            db_url = str(Path(tmp) / "demo.db")
            status.update("building the full demo study (36 participants)")
            run_demo(db_url, seed=1, progress=status_progress(status))
        status.update(f"starting `study tui` {runs} times")
        result = run_bench(db_url, overview_seconds, runs)
    click.echo(
        f"study tui, {result.participants} participants: overview after "
        f"{result.median_s:.2f} s (median of {runs}; "
        f"{', '.join(f'{s:.2f}' for s in result.seconds)} s); target <= {result.target_s} s; "
        f"CPU per run (start to exit) {', '.join(f'{s:.2f}' for s in result.cpu_seconds)} s; "
        f"the app's own part (make_app to overview, headless) "
        f"{', '.join(f'{s:.2f}' for s in result.app_seconds)} s; "
        f"quit {', '.join(f'{s:.2f}' for s in result.quit_seconds)} s; "
        f"F3 to run screen ready {', '.join(f'{s:.2f}' for s in result.run_ready_seconds)} s; "
        f"quit while preparing {', '.join(f'{s:.2f}' for s in result.quit_preparing_seconds)} s"
    )
    write_json(json_path, result.to_dict())


@bench.command("startup")
@click.option(
    "--runs",
    type=click.IntRange(min=1),
    default=5,
    show_default=True,
    help="Fresh processes per figure (after one warm-up each); the median counts.",
)
@click.option(
    "--db",
    "db_url",
    metavar="URL",
    default=None,
    help="Study database for `study analyze` and the run screen, e.g. made by "
    "`study demo` [default: a quick 6-participant demo study built first].",
)
@click.option(
    "--rows",
    type=click.IntRange(min=1),
    default=1_000_000,
    show_default=True,
    help="Samples written by the writer and by plain sqlite3, each run.",
)
@click.option(
    "--demo-runs",
    type=click.IntRange(min=0),
    default=1,
    show_default=True,
    help="Timed runs of the whole `study demo` (after a warm-up); 0 leaves it out.",
)
@_json_option
def bench_startup(
    db_url: str | None, runs: int, rows: int, demo_runs: int, json_path: Path | None
) -> None:
    """From a cold process: simulate, the run screen, analyze, the writer, the demo.

    \b
    Example:
      study bench startup --json startup.json
    """
    # lazy: study.bench.startup costs 12 ms at start-up
    from study.bench.startup import bench_startup as run_bench

    if json_path is not None:
        check_parent_folder(json_path)
    with Console(stderr=True).status("startup") as status:
        result = run_bench(
            runs, db_url, rows, progress=status_progress(status), demo_runs=demo_runs
        )

    def line(name: str, t) -> str:
        each = ", ".join(f"{s:.2f}" for s in t.seconds)
        n = len(t.seconds)
        return f"{name}: {t.median_s:.2f} s (median of {n}; {each}); target <= {t.target_s} s"

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
    if result.demo is not None:
        click.echo(line("study demo, the whole 36-participant study", result.demo))
    load = ", ".join(f"{x:.2f}" for x in result.load_average)
    click.echo(f"load average {load}")
    write_json(json_path, result.to_dict())


@bench.command("participants")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Write participants_bench.md and the fit's figure here.",
)
@click.option(
    "--trials",
    type=click.IntRange(min=1),
    default=3,
    show_default=True,
    help="Measured trials per condition in the simulated study.",
)
@click.option(
    "--truth-people",
    type=click.IntRange(min=4),
    default=300,
    show_default=True,
    help="People per group simulated for the truth's HV - VO differences.",
)
@click.option(
    "--truth-shift",
    type=click.FloatRange(min=0.0, max=2.0),
    default=0.7,
    show_default=True,
    help="How far the truth's trait means lie from the priors', in prior SDs (0: the priors).",
)
@click.option(
    "--weak-traits",
    type=click.Choice(WEAK_TRAITS),
    default="prior",
    show_default=True,
    help="As `study participants fit --weak-traits`.",
)
@click.option(
    "--probes", is_flag=True, help="The simulated people answer the design's probes before the fit."
)
@click.option(
    "--coverage",
    "coverage_studies",
    type=click.IntRange(min=0),
    default=50,
    show_default=True,
    help="Studies simulated on the fit's emulator to check the "
    "coverage of the fitted means' 95 % intervals (0: skip).",
)
@click.option(
    "--bootstrap",
    type=click.IntRange(min=20),
    default=100,
    show_default=True,
    help="As `study participants fit --bootstrap` (also the coverage's).",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=2,
    show_default=True,
    help="Processes that run the simulations side by side.",
)
@click.option(
    "--seed", type=SEED, default=11, show_default=True, help="Seed of the simulated studies."
)
@_json_option
def bench_participants(
    out_dir: Path | None,
    trials: int,
    truth_people: int,
    truth_shift: float,
    weak_traits: str,
    probes: bool,
    coverage_studies: int,
    bootstrap: int,
    jobs: int,
    seed: int,
    json_path: Path | None,
) -> None:
    """Recovery of known trait distributions from a simulated 20/8/8 study, and the fit's time.

    \b
    Example:
      study bench participants --json participants.json
    """
    # lazy: study.analysis.participant_fit.fit (with scipy, sklearn, pandas) costs 1.7 s at start-up
    from study.analysis.participant_fit.fit import FitSettings

    # lazy: study.bench.participants (with scipy, sklearn, pandas) costs 1.7 s at start-up
    from study.bench.participants import markdown, run_participants_bench

    if json_path is not None:
        check_parent_folder(json_path)
    with Console(stderr=True).status("participants bench") as status:
        report = run_participants_bench(
            {"outsider": 20, "novice": 8, "expert": 8},
            trials,
            FitSettings(jobs=jobs, weak_traits=weak_traits, bootstrap=bootstrap),
            truth_people,
            seed,
            out_dir,
            status_progress(status),
            truth_shift,
            probes,
            coverage_studies,
        )
    text = markdown(report)
    if out_dir is not None:
        (out_dir / "participants_bench.md").write_text(text)
    click.echo(text)
    write_json(json_path, report)


@bench.command("lsl", cls=StudyCommand)
@_json_option
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for the Markdown table and the JSON.",
)
@click.option("--quick", is_flag=True, help="Two trials of 2 s (a few seconds in all).")
def bench_lsl(json_path: Path | None, out_dir: Path, quick: bool) -> None:
    """Recorded LSL streams against the trial's clock: the alignment error of a simulated
    1 kHz instrument during a paced session (needs LSLAPICFG, see `study lsl-config`).

    \b
    Example:
      study bench lsl --out lsl/
    """
    # lazy: study.bench.lsl (with numpy) costs 76 ms at start-up
    from study.bench.lsl import LslBenchConfig, run_lsl_bench

    load_pylsl()  # one line now, rather than from the instrument's process
    config = LslBenchConfig.quick() if quick else LslBenchConfig()
    with Console(stderr=True).status("LSL bench") as line:
        report = run_lsl_bench(config, out_dir, status_progress(line))
    write_json(json_path, report)
    click.echo((out_dir / "lsl_bench.md").read_text())
