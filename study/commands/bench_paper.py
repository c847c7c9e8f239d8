"""`study bench follower|master|lcca|calibrate|notes`: the paper's tables and figures
regenerated on the simulated hardware, each written as Markdown, JSON and figures.

The commands are added to the `study bench` group in `study.commands.bench`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import click

from study.commands.base import (
    SEED,
    StudyCommand,
    check_parent_folder,
    count_option,
    json_option,
    out_dir_option,
    status_progress,
)
from study.errors import StudyInputError
from teleop_core.progress import Progress

_json_option = json_option("Write every table as JSON here.")
_out_option = out_dir_option("Folder for the Markdown tables, the figures and any data files.")
_seed_option = click.option(
    "--seed", type=SEED, default=0, show_default=True, help="Seed of the simulated recordings."
)


def write_json(json_path: Path | None, data: dict[str, Any]) -> None:
    """Write a bench's report as indented JSON (nothing when no --json was given)."""
    if json_path is not None:
        json_path.write_text(json.dumps(data, indent=2) + "\n")


def _run_report(
    json_path: Path,
    markdown: Path,
    status: str,
    run: Callable[[Progress], dict[str, Any]],
) -> None:
    """Run a bench under a status line on stderr, write its JSON, show its Markdown
    (the command has checked the JSON's folder before loading anything)."""
    # lazy: rich.console costs 23 ms at start-up
    from rich.console import Console

    with Console(stderr=True).status(status) as line:
        report = run(status_progress(line))
    write_json(json_path, report)
    click.echo(markdown.read_text())


def _run_with_estimator(
    json_path: Path,
    model_dir: Path | None,
    markdown: Path,
    status: str,
    run: Callable[[Any, Progress], dict[str, Any]],
) -> None:
    """`_run_report` of a bench that runs the force estimator of --estimator (loaded
    after the JSON's folder is checked): `run(estimator, progress)`."""
    # lazy: study.protocol.default_estimator (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.protocol.default_estimator import load_estimator

    check_parent_folder(json_path)
    estimator = load_estimator(model_dir)
    _run_report(json_path, markdown, status, lambda progress: run(estimator, progress))


def _estimator_bench(
    name: str, estimator_help: str, quick_help: str
) -> Callable[[Callable[..., Any]], click.Command]:
    """`study bench NAME --json --out --estimator --seed --quick`: a bench that runs the
    force estimator (the options in that order, as --help lists them)."""

    def command(f: Callable[..., Any]) -> click.Command:
        for option in reversed(
            (
                _json_option,
                _out_option,
                click.option(
                    "--estimator",
                    "model_dir",
                    type=click.Path(file_okay=False, path_type=Path),
                    help=estimator_help,
                ),
                _seed_option,
                click.option("--quick", is_flag=True, help=quick_help),
            )
        ):
            f = option(f)
        return click.command(name, cls=StudyCommand)(f)

    return command


@click.command("follower", cls=StudyCommand)
@_json_option
@_out_option
@_seed_option
@click.option(
    "--quick",
    is_flag=True,
    help="Tiny data and 1-2 epochs: checks the pipeline in seconds, measures nothing.",
)
@click.option(
    "--only",
    type=click.Choice(["tables", "generalisation", "training"]),
    default=None,
    help="Run one part: the paper's tables, the estimator trained on the first 60 % of "
    "recordings with unmodelled effects and run on the rest, or the time `study estimator "
    "train` takes on 60,000 samples [default: all].",
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
    """Tables I-III and Fig. 8 of the endovascular haptics paper on the simulated follower,
    and the estimator on recordings it never saw, and the training time of `study
    estimator train` (about 30 min, several hours and 10 min).

    \b
    Example:
      study bench follower --json follower.json --out follower/
    """
    # lazy: study.bench.follower (with torch, scipy, statsmodels) costs 3.1 s at start-up
    from study.bench.follower import PARTS, FollowerBenchConfig, run_follower_bench

    check_parent_folder(json_path)
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
    _run_report(
        json_path,
        out_dir / "follower_bench.md",
        "follower bench",
        lambda progress: run_follower_bench(config, out_dir, progress=progress),
    )


@_estimator_bench(
    "master",
    "Force estimator folder for the closed loop [default: the model shipped with haptic-study].",
    "Short runs: checks the pipeline, measures little.",
)
def bench_master(
    json_path: Path, out_dir: Path, model_dir: Path | None, seed: int, quick: bool
) -> None:
    """Figs. 10-11 of the endovascular haptics paper on the simulated dial, latency, and the
    loop's speed.

    \b
    Example:
      study bench master --json master.json --out master/
    """
    # lazy: study.bench.master (with pandas, pyarrow, matplotlib) costs 0.8 s at start-up
    from study.bench.master import MasterBenchConfig, run_master_bench

    config = replace(MasterBenchConfig.quick() if quick else MasterBenchConfig(), seed=seed)
    _run_with_estimator(
        json_path,
        model_dir,
        out_dir / "master_bench.md",
        "master bench",
        lambda estimator, progress: run_master_bench(
            config, out_dir, estimator=estimator, progress=progress
        ),
    )


@click.option(
    "--lsl",
    is_flag=True,
    help="Publish every trial's samples as an LSL stream, timed with the trial "
    "(needs LSLAPICFG, see `study lsl-config`).",
)
@_estimator_bench(
    "lcca",
    "Force estimator folder [default: the model shipped with haptic-study].",
    "Two participants per group, 60 s at most each.",
)
def bench_lcca(
    json_path: Path,
    out_dir: Path,
    model_dir: Path | None,
    seed: int,
    quick: bool,
    lsl: bool = False,
) -> None:
    """The paper's 20/8/8 user study with simulated participants, and its speed.

    \b
    Example:
      study bench lcca --json lcca.json --out lcca/
    """
    # lazy: study.bench.lcca (with scipy, pandas, pyarrow) costs 1.6 s at start-up
    from study.bench.lcca import LccaBenchConfig, run_lcca_bench

    config = replace(
        LccaBenchConfig.quick() if quick else LccaBenchConfig(), seed=seed, publish_lsl=lsl
    )
    _run_with_estimator(
        json_path,
        model_dir,
        out_dir / "lcca_bench.md",
        "simulated study",
        lambda estimator, progress: run_lcca_bench(config, estimator, out_dir, progress=progress),
    )


@click.command("calibrate", cls=StudyCommand)
@_json_option
@out_dir_option(
    "Folder for the Markdown table and a copy of the JSON [default: next to --json].",
    required=False,
)
@_seed_option
@click.option("--epochs", type=click.IntRange(min=1), default=None, help="GRU epochs [30].")
@click.option("--quick", is_flag=True, help="One-minute recordings at 100 Hz, 2 epochs.")
@click.option(
    "--only-open",
    is_flag=True,
    help="Only measured data (EMPS), effects outside the families, clean seeds.",
)
@click.option(
    "--generalise",
    is_flag=True,
    help="The generalisation bench instead: every family and mixtures of two and three, "
    "random parameters and strengths (0.5-3 JND), clean recordings; shares per family.",
)
@click.option(
    "--count",
    type=click.IntRange(min=1),
    default=None,
    help="With --generalise: recordings per family, per mixture size and clean "
    "[20 per family and mixture size, 50 clean; 1 each with --quick].",
)
@click.option(
    "--time",
    "timing",
    is_flag=True,
    help="How long `study calibrate` takes instead: 4-minute 200 Hz recordings (clean, "
    "one effect, three, a ripple) and EMPS, each run twice in a fresh process; CPU and "
    "wall seconds, load average (--seed: the simulated recordings').",
)
@click.option(
    "--family",
    "only",
    multiple=True,
    metavar="NAME",
    help="With --generalise: only this group (a family, 'mixtures' or 'clean'; repeat "
    "for more); each recording keeps the seed it has in the whole bench [all].",
)
def bench_calibrate(
    json_path: Path,
    out_dir: Path | None,
    seed: int,
    epochs: int | None,
    quick: bool,
    only_open: bool,
    generalise: bool,
    count: int | None,
    timing: bool,
    only: tuple[str, ...],
) -> None:
    """Calibration loop: every family, the clean recording, speed, estimator.

    \b
    Example:
      study bench calibrate --json calibrate.json
    """
    # lazy: study.bench.calibrate (with scipy, statsmodels, pandas) costs 1.3 s at start-up
    from study.bench.calibrate import CalibrateBenchConfig, run_calibrate_bench

    check_parent_folder(json_path)
    if count is not None and not generalise:
        raise StudyInputError(f"--count {count}; expected it only with --generalise")
    if only and not generalise:
        raise StudyInputError(f"--family {only[0]}; expected it only with --generalise")
    if timing:
        _bench_calibrate_time(json_path, out_dir, seed, quick, generalise or only_open)
        return
    if generalise:
        from study.bench.calibrate_general import (
            GROUP_WORDS,
            GeneraliseConfig,
            run_generalise_bench,
        )
        from teleop_core.calibration.general import FAMILIES

        unknown = [g for g in only if g not in (*FAMILIES, *GROUP_WORDS)]
        if unknown:
            raise StudyInputError(
                f"--family {unknown[0]}; expected one of {', '.join((*FAMILIES, *GROUP_WORDS))}"
            )

        general = GeneraliseConfig.quick(count or 1) if quick else GeneraliseConfig()
        if count is not None and not quick:
            general = replace(
                general,
                per_family=count,
                mixtures_of_two=count,
                mixtures_of_three=count,
                clean=count,
            )
        general = replace(general, seed=seed, only=only)
        folder = out_dir or json_path.parent
        _run_report(
            json_path,
            folder / "calibrate_general.md",
            "calibration generalisation bench",
            lambda say: run_generalise_bench(general, folder, say),
        )
        return
    config = CalibrateBenchConfig.quick() if quick else CalibrateBenchConfig()
    config = replace(config, seed=seed, **({"epochs": epochs} if epochs else {}))
    folder = out_dir or json_path.parent
    _run_report(
        json_path,
        folder / "calibrate_bench.md",
        "calibration bench",
        lambda progress: run_calibrate_bench(
            config, folder, progress=progress, only_open=only_open
        ),
    )


def _bench_calibrate_time(
    json_path: Path, out_dir: Path | None, seed: int, quick: bool, other: bool
) -> None:
    """`study bench calibrate --time` (`study.bench.calibrate_time`)."""
    # lazy: study.bench.calibrate_time (with scipy, statsmodels, pandas) costs 1.3 s at start-up
    from study.bench.calibrate_time import CalibrateTimeConfig, run_calibrate_time_bench

    if other:
        raise StudyInputError("--time; expected it without --generalise and --only-open")
    config = replace(CalibrateTimeConfig.quick() if quick else CalibrateTimeConfig(), seed=seed)
    folder = out_dir or json_path.parent
    _run_report(
        json_path,
        folder / "calibrate_time.md",
        "timing study calibrate",
        lambda progress: run_calibrate_time_bench(config, folder, progress),
    )


@click.command("notes", cls=StudyCommand)
@_json_option
@_out_option
@count_option("--draws", 10, "Seeded parameter draws per axis for the identification round trip.")
@count_option("--trials", 4, "Simulated NOTES trials per group and condition.")
@count_option(
    "--surgeons",
    10,
    "Simulated experts for the surgeons' benchmark (the NOTES paper had 10).",
    minimum=2,
)
@_seed_option
def bench_notes(
    json_path: Path, out_dir: Path, draws: int, trials: int, surgeons: int, seed: int
) -> None:
    """The NOTES device of the NOTES haptics paper: bandwidth, settling, limits,
    identification round trip, and the surgeons' benchmark on simulated experts.

    \b
    Example:
      study bench notes --json notes.json --out notes/
    """
    # lazy: study.bench.notes (with scipy, pandas, pyarrow) costs 1.1 s at start-up
    from study.bench.notes import NotesBenchConfig, run_notes_bench

    check_parent_folder(json_path)
    config = NotesBenchConfig(draws=draws, seed=seed, trials=trials, surgeons=surgeons)
    _run_report(
        json_path,
        out_dir / "notes_bench.md",
        "NOTES bench",
        lambda progress: run_notes_bench(config, out_dir, progress=progress),
    )


PAPER_BENCHES = (bench_follower, bench_master, bench_lcca, bench_calibrate, bench_notes)
