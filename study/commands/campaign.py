"""`study campaign template|run|report`: simulation campaigns on Dask (study.campaign)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.console import Console

from study.commands.base import StudyGroup, progress_bar
from study.errors import StudyInputError

if TYPE_CHECKING:
    from study.campaign.store import CampaignDir


@click.group("campaign", cls=StudyGroup)
def campaign() -> None:
    """Simulation campaigns: power and parameter sweeps of simulated studies on Dask.

    \b
    Example:
      study campaign template > campaign.toml && study campaign run campaign.toml --out sweep/
    """


@campaign.command("template")
def template() -> None:
    """Print a commented campaign file (TOML) to start from.

    \b
    Example:
      study campaign template > campaign.toml
    """
    # lazy: study.campaign.spec (with numpy) costs 0.1 s at start-up
    from study.campaign.spec import TEMPLATE

    click.echo(TEMPLATE, nl=False)


@campaign.command("run")
@click.argument(
    "campaign_path", metavar="CAMPAIGN.toml", type=click.Path(dir_okay=False, path_type=Path)
)
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Results folder; a folder holding this campaign is resumed.",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    default=None,
    help="Worker processes of the embedded Dask LocalCluster [default: 1].",
)
@click.option(
    "--scheduler",
    metavar="tcp://HOST:PORT",
    default=None,
    help="Run on this Dask scheduler's workers instead of a LocalCluster.",
)
def run(campaign_path: Path, out_dir: Path, workers: int | None, scheduler: str | None) -> None:
    """Run CAMPAIGN.toml's units (skipping those already in --out) and write the results.

    \b
    Example:
      study campaign run campaign.toml --out sweep/
    """
    # lazy: study.campaign.engine (with scipy, statsmodels, pandas) costs 1.8 s at start-up
    from study.campaign.engine import close_client, open_client, run_pending

    # lazy: study.campaign.spec (with numpy) costs 0.1 s at start-up
    from study.campaign.spec import parse_campaign

    # lazy: study.campaign.store (with scipy, statsmodels, pandas) costs 1.5 s at start-up
    from study.campaign.store import CampaignDir

    if workers is not None and scheduler is not None:
        raise StudyInputError(
            f"--workers {workers} with --scheduler {scheduler}; expected one of them "
            "(the scheduler's workers are started with `dask worker`)"
        )
    # lazy: study.protocol.csv_input (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.protocol.csv_input import read_text_file

    text = read_text_file(campaign_path, "campaign file", "a UTF-8 TOML file")
    spec = parse_campaign(text, str(campaign_path))
    folder = CampaignDir.open(out_dir, spec, text)
    total = len(spec.units())
    todo = len(folder.pending())
    click.echo(
        f"{spec.name}: {len(spec.cells())} cells x {spec.replicates} replicates = "
        f"{total} simulated studies; {total - todo} already in {out_dir}"
    )
    if todo:
        err = Console(stderr=True)
        with err.status("starting Dask" if scheduler is None else f"connecting to {scheduler}"):
            client = open_client(workers, scheduler)
        try:
            folder.create()
            with progress_bar(transient=False, console=err) as bar:
                task = bar.add_task("units", total=total, completed=total - todo)
                run_pending(
                    folder,
                    client,
                    on_start=lambda i: bar.console.print(
                        f"Dask: {i.workers} workers, dashboard {i.dashboard}"
                    ),
                    on_unit=lambda _: bar.advance(task),
                )
        finally:
            close_client(client)
    folder.create()
    _write_outputs(folder)


@campaign.command("report")
@click.argument("out_dir", metavar="DIR", type=click.Path(file_okay=False, path_type=Path))
def report(out_dir: Path) -> None:
    """Rebuild DIR's tables from its finished units and redraw the figures.

    \b
    Example:
      study campaign report sweep/
    """
    # lazy: study.campaign.store (with scipy, statsmodels, pandas) costs 1.5 s at start-up
    from study.campaign.store import CampaignDir

    if not out_dir.is_dir():
        raise StudyInputError(f"campaign folder {out_dir} does not exist")
    _write_outputs(CampaignDir.existing(out_dir))


def _write_outputs(folder: CampaignDir) -> None:
    # lazy: study.campaign.figures (with pandas, pyarrow, matplotlib) costs 0.8 s at start-up
    from study.campaign.figures import draw_figures

    results, summary = folder.write_tables()
    spec = folder.spec
    done = results[["replicate", *spec.factors]].drop_duplicates().shape[0] if len(results) else 0
    total = len(spec.units())
    state = "complete" if done == total else f"INCOMPLETE: {done} of {total} units"
    click.echo(
        f"results ({state}, simulated): {folder.root / 'results.csv'}, "
        f"{folder.root / 'summary.csv'}"
    )
    if len(summary):
        for path in draw_figures(summary, list(spec.factors), spec.name, folder.root / "figures"):
            if path.suffix == ".png":
                click.echo(f"figure: {path}")
