"""`study campaign`: simulated-study campaigns on Dask, deterministic and resumable.

The reference for every distributed run is the same campaign computed serially in the
test process (`_serial`); a unit itself is checked against `study run` on a database.
"""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from distributed import Client, LocalCluster
from sqlalchemy import create_engine, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import Trial
from study.campaign.engine import run_pending
from study.campaign.spec import TEMPLATE, parse_campaign, study_seed
from study.campaign.store import CampaignDir, summarise
from study.campaign.unit import run_unit, simulate_study
from study.cli import main

REPO = Path(__file__).resolve().parents[2]
NOTES = """\
name = "tiny NOTES campaign"
seed = 11
replicates = 2
task = "notes"
trials_per_condition = 1
[groups]
novice = 3
expert = 3
[factors]
group_scale = [1.0, 1.34]
"""
"""4 units of 12-16 NOTES trials (~0.1 s each): cells of 3/3 and 4/4 participants."""
LCCA = """\
name = "tiny LCCA campaign"
seed = 5
replicates = 1
task = "lcca"
[groups]
expert = 3
[factors]
haptic_gain = [0.0, 0.02]
link_delay_ms = [0, 40]
"""
"""4 units of 6 LCCA trials: the link and the gain reach the loop."""


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}


def _serial(text: str, root: Path) -> bytes:
    """The campaign computed unit by unit in this process, written as `run` writes it."""
    spec = parse_campaign(text)
    folder = CampaignDir.open(root, spec, text)
    folder.create()
    for cell, r in spec.units():
        rows, seconds = run_unit(spec, cell, r)
        folder.save_unit(cell, r, rows, seconds)
    folder.write_tables()
    return (root / "results.csv").read_bytes()


@pytest.fixture(scope="module")
def notes_reference(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    return _serial(NOTES, tmp_path_factory.mktemp("serial") / "out")


def _cluster_run(text: str, root: Path, workers: int) -> bytes:
    spec = parse_campaign(text)
    folder = CampaignDir.open(root, spec, text)
    folder.create()
    with (
        LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            host="127.0.0.1",
        ) as cluster,
        Client(cluster) as c,
    ):
        assert len(c.scheduler_info()["workers"]) == workers
        assert run_pending(folder, c) == len(spec.units())
    folder.write_tables()
    return (root / "results.csv").read_bytes()


def test_template_is_a_valid_campaign_of_the_papers_groups(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["campaign", "template"]) == 0
    spec = parse_campaign(capsys.readouterr().out)
    assert spec.groups == {"outsider": 20, "novice": 8, "expert": 8}
    assert [c.values["group_scale"] for c in spec.cells()] == [0.5, 1.0, 1.5]
    assert len(spec.units()) == 3 * 50
    # 20/8/8 x 0.5 and x 1.5, rounded
    assert [spec.sizes(c) for c in spec.cells()][0::2] == [
        {"outsider": 10, "novice": 4, "expert": 4},
        {"outsider": 30, "novice": 12, "expert": 12},
    ]
    # replicate r has the same study seed in every cell, and replicates differ
    assert study_seed(1, 0) != study_seed(1, 1)
    assert TEMPLATE.count("SIMULATED") == 1


@pytest.mark.parametrize(
    "change, message",
    [
        (("replicates = 2", "replicates = 0"), "replicates = 0"),
        (("group_scale = [1.0, 1.34]", "group_scale = [1.0, 0.5]"), "group_scale 0.5"),
        (("group_scale = [1.0, 1.34]", "haptic_gain = [0.01]"), "factors.haptic_gain"),
        (("group_scale = [1.0, 1.34]", "gain = [1]"), "unknown factor 'gain'"),
        (('task = "notes"', 'task = "suturing"'), "'suturing'"),
        (("novice = 3", "surgeon = 3"), "groups.surgeon"),
        (("seed = 11", 'seed = "x"'), "seed = 'x'"),
    ],
)
def test_bad_campaign_file_is_one_line_exit_2_and_nothing_written(
    change: tuple[str, str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "c.toml"
    path.write_text(NOTES.replace(*change))
    assert main(["campaign", "run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert message in err[0], err
    assert not (tmp_path / "out").exists()


def test_bad_loss_scheduler_and_folder_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lossy = tmp_path / "lossy.toml"
    lossy.write_text(LCCA.replace("link_delay_ms = [0, 40]", "link_loss = [0.1, 1.0]"))
    path = tmp_path / "c.toml"
    path.write_text(NOTES)
    out = str(tmp_path / "out")
    cases = [
        (["campaign", "run", str(lossy), "--out", out], "link_loss value 1"),
        (["campaign", "run", str(path), "--out", out, "--scheduler", "localhost"], "'localhost'"),
        (
            [
                "campaign",
                "run",
                str(path),
                "--out",
                out,
                "--workers",
                "2",
                "--scheduler",
                "tcp://127.0.0.1:1",
            ],
            "--workers 2 with --scheduler",
        ),
        (["campaign", "run", str(tmp_path / "none.toml"), "--out", out], "none.toml"),
        (["campaign", "report", out], "does not exist"),
    ]
    for argv, message in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        assert message in err[0], err
        assert not Path(out).exists()
    # a folder holding another campaign is not overwritten
    other = tmp_path / "other"
    CampaignDir.open(other, parse_campaign(LCCA), LCCA).create()
    assert main(["campaign", "run", str(path), "--out", str(other)]) == 2
    assert "holds another campaign" in capsys.readouterr().err
    assert (other / "campaign.toml").read_text() == LCCA


def test_power_interval_is_wilsons_and_effect_interval_t_based() -> None:
    # 10 replicates of one cell, 8 significant (6 of them with HV below VO)
    results = pd.DataFrame(
        {
            "group_scale": 1.0,
            "group": "novice",
            "measure": "peak_proximal_force_n",
            "n": 8,
            "significant": [True] * 8 + [False] * 2,
            "mean_vo": [1.0] * 10,
            "mean_hv": [0.5] * 6 + [1.5] * 4,
            "effect": np.arange(10, dtype=float) / 10,
        }
    )
    row = summarise(results, ["group_scale"], ["novice"]).iloc[0]
    # Wilson score interval, closed form: (p + z^2/2n +- z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)
    z, n, p = 1.959963984540054, 10, 0.8
    centre, half = p + z**2 / (2 * n), z * math.sqrt(p * (1 - p) / n + z**2 / (4 * n**2))
    assert row["power"] == 0.8
    assert row["power_hv_lower"] == 0.6
    assert row["power_ci_low"] == pytest.approx((centre - half) / (1 + z**2 / n), abs=1e-12)
    assert row["power_ci_high"] == pytest.approx((centre + half) / (1 + z**2 / n), abs=1e-12)
    # mean 0.45, sd of 0..0.9 step 0.1 = 0.30277, t(0.975, 9) = 2.262157 (R: qt(0.975, 9))
    assert row["effect_mean"] == pytest.approx(0.45)
    assert row["effect_ci_high"] - 0.45 == pytest.approx(
        2.262157 * 0.3027650 / math.sqrt(10), rel=1e-6
    )
    assert row["data_source"] == "simulated"


def test_a_unit_is_the_study_that_study_run_simulates(tmp_path: Path) -> None:
    """The same design and seed through `study init/participant add/run` give the same
    trials, measure for measure, as the campaign's unit."""
    spec = parse_campaign(LCCA.replace("link_delay_ms = [0, 40]", ""))
    cell = spec.cells()[1]  # haptic_gain 0.02: the device's default, as `study run` uses
    seed = study_seed(spec.seed, 0)
    design = tmp_path / "d.toml"
    design.write_text(
        f"seed = {seed}\ntrials_per_condition = 1\npractice_trials = 0\n[groups]\nexpert = 3\n"
    )
    db = str(tmp_path / "s.db")
    assert main(["init", "--design", str(design), "--db", db]) == 0
    for _ in range(3):
        assert main(["participant", "add", "--group", "expert", "--db", db]) == 0
    assert main(["run", "--all", "--jobs", "1", "--db", db]) == 0
    engine = create_engine(f"sqlite:///{db}")
    with Session(engine) as s:
        stored = pd.DataFrame(
            [
                (
                    code,
                    t.condition,
                    t.completion_time_s,
                    t.measure_values["peak_proximal_force_n"],
                    t.measure_values["peak_distal_force_n"],
                )
                for code, t in s.execute(
                    select(Participant.code, Trial)
                    .join(Trial)
                    .order_by(Participant.code, Trial.condition)
                )
            ],
            columns=[
                "participant",
                "condition",
                "completion_time_s",
                "peak_proximal_force_n",
                "peak_distal_force_n",
            ],
        )
    engine.dispose()
    unit = simulate_study(spec, cell, 0).sort_values(["participant", "condition"])
    columns = list(stored.columns)
    assert len(stored) == 6
    pd.testing.assert_frame_equal(unit[columns].reset_index(drop=True), stored, rtol=1e-12)
    # the link factor reaches the loop: 40 ms each way changes the forces
    delayed = parse_campaign(LCCA).cells()[3]
    assert delayed.values == {**cell.values, "link_delay_ms": 40.0}
    assert not simulate_study(spec, delayed, 0)[columns[2:]].equals(unit[columns[2:]])


def test_one_and_two_workers_give_the_serial_results_byte_for_byte(
    notes_reference: bytes, tmp_path: Path
) -> None:
    one = _cluster_run(NOTES, tmp_path / "one", workers=1)
    two = _cluster_run(NOTES, tmp_path / "two", workers=2)
    assert one == notes_reference
    assert two == notes_reference
    results = pd.read_csv(tmp_path / "two" / "results.csv")
    # one row per unit x group x measure, in grid order
    assert len(results) == 4 * 2 * 3
    assert list(results.columns[:5]) == ["group_scale", "replicate", "group", "measure", "n"]
    assert {"mean_vo", "mean_hv", "effect", "p", "significant"} <= set(results.columns)
    assert results["n"].tolist() == [3] * 12 + [4] * 12
    assert set(results["data_source"]) == {"simulated"}


def _spawn(argv: list[str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        argv,
        env=_env(),
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def _stop(process: subprocess.Popen[bytes]) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGKILL)
    process.wait(30)


def _wait_for(predicate: object, timeout_s: float = 120.0) -> None:
    end = time.monotonic() + timeout_s
    while not predicate():  # type: ignore[operator]
        if time.monotonic() > end:
            raise TimeoutError("condition not reached")
        time.sleep(0.1)


def test_a_killed_campaign_resumes_to_the_uninterrupted_results(
    notes_reference: bytes, tmp_path: Path
) -> None:
    path, out = tmp_path / "c.toml", tmp_path / "out"
    path.write_text(NOTES)
    run = _spawn(
        [
            sys.executable,
            "-m",
            "study.cli",
            "campaign",
            "run",
            str(path),
            "--out",
            str(out),
            "--workers",
            "1",
        ]
    )
    try:
        _wait_for(lambda: len(list((out / "units").glob("*.parquet"))) >= 1)
    finally:
        _stop(run)  # kill -9 of the client and its LocalCluster
    done = {p.name: p.stat().st_mtime_ns for p in (out / "units").glob("*.parquet")}
    assert 1 <= len(done) < 4
    assert not (out / "results.csv").exists()
    assert main(["campaign", "run", str(path), "--out", str(out), "--workers", "1"]) == 0
    assert (out / "results.csv").read_bytes() == notes_reference
    # the units finished before the kill were not run again
    assert all((out / "units" / n).stat().st_mtime_ns == t for n, t in done.items())
    assert len(CampaignDir.existing(out).unit_times()) == 4


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def dask_cluster() -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """`dask scheduler` and two `dask worker` processes on 127.0.0.1."""
    dask = str(Path(sys.executable).parent / "dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = [
        _spawn([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"])
    ]
    try:
        with Client(address, timeout=60):
            pass
        for _ in range(2):
            processes.append(
                _spawn(
                    [
                        dask,
                        "worker",
                        address,
                        "--nthreads",
                        "1",
                        "--no-dashboard",
                        "--host",
                        "127.0.0.1",
                    ]
                )
            )
        with Client(address, timeout=60) as c:
            c.wait_for_workers(2, timeout=120)
        yield address, processes
    finally:
        for p in reversed(processes):
            _stop(p)


def test_an_external_scheduler_runs_it_and_a_lost_worker_costs_one_unit(
    dask_cluster: tuple[str, list[subprocess.Popen[bytes]]],
    notes_reference: bytes,
    tmp_path: Path,
) -> None:
    address, processes = dask_cluster
    path, out = tmp_path / "c.toml", tmp_path / "out"
    path.write_text(NOTES)
    run = _spawn(
        [
            sys.executable,
            "-m",
            "study.cli",
            "campaign",
            "run",
            str(path),
            "--out",
            str(out),
            "--scheduler",
            address,
        ]
    )
    try:
        _wait_for(lambda: len(list((out / "units").glob("*.parquet"))) >= 1)
        _stop(processes[1])  # one `dask worker` dies, whatever it was running
        assert run.wait(180) == 0
    finally:
        _stop(run)
    assert (out / "results.csv").read_bytes() == notes_reference


def test_report_redraws_labelled_figures(
    notes_reference: bytes, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    _serial(NOTES, out)
    assert main(["campaign", "report", str(out)]) == 0
    assert "complete, simulated" in capsys.readouterr().out
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert figures == [
        "effect_group_scale.pdf",
        "effect_group_scale.png",
        "power_group_scale.pdf",
        "power_group_scale.png",
    ]
    assert (out / "results.csv").read_bytes() == notes_reference
    import json

    assert json.loads((out / "campaign.json").read_text())["data_source"] == "simulated"


def test_bench_campaign_runs_both_clusters_and_reports_identical_results(tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    assert (
        main(["bench", "campaign", "--replicates", "2", "--group-size", "3", "--json", str(out)])
        == 0
    )
    report = json.loads(out.read_text())
    assert [r["workers"] for r in report["runs"]] == [1, 2]
    assert all(r["units"] == 2 and len(r["unit_seconds"]) == 2 for r in report["runs"])
    assert report["identical_results"] is True
    # the speed-up is the ratio of the two runs' throughputs, as reported
    one, two = report["runs"]
    assert report["speedup"] == pytest.approx(two["units_per_hour"] / one["units_per_hour"])
    assert "simulated" in report["note"]
