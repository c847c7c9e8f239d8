"""`study bench campaign`: what Dask gives a campaign on this machine.

One small campaign (a few simulated studies at the physics level) runs twice from
scratch, on a `LocalCluster` of 1 worker and of N workers, in fresh folders. For each:

- units per hour, from the wall time of `run_pending` (the workers' warm-up, when numba
  loads the loop's kernel and the estimator is read, happens before the clock starts:
  `WarmUp` runs at worker start, and the cluster is up before `run_pending`);
- the units' own run time (`compute_unit`'s seconds, measured inside the worker);
- Dask's overhead per unit: wall x workers / sum of the units' own times - 1, i.e. the
  share of the workers' time not spent simulating (scheduling, transfer, writing the
  results, and the idle tail when fewer units than workers remain).

The speed-up is N-worker units per hour over 1-worker units per hour; a result is only
valid when both runs give the same `results.csv` (checked, byte for byte).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from teleop_core.progress import Progress

TOML = """\
name = "bench campaign"
seed = 3
replicates = {replicates}
task = "lcca"
trials_per_condition = 1

[groups]
outsider = {n}
novice = {n}
expert = {n}

[factors]
haptic_gain = [0.02]
"""


@dataclass
class WorkerRun:
    workers: int
    units: int
    wall_s: float
    unit_seconds: list[float]
    results_sha256: str

    @property
    def units_per_hour(self) -> float:
        return 3600.0 * self.units / self.wall_s

    @property
    def overhead(self) -> float:
        """Share of the workers' wall time not spent inside the units."""
        return self.wall_s * self.workers / sum(self.unit_seconds) - 1.0

    def to_dict(self) -> dict[str, Any]:
        return {
            **asdict(self),
            "units_per_hour": self.units_per_hour,
            "mean_unit_s": sum(self.unit_seconds) / len(self.unit_seconds),
            "overhead": self.overhead,
        }


@dataclass
class CampaignBench:
    replicates: int
    group_size: int
    runs: list[WorkerRun] = field(default_factory=list)
    load_average: tuple[float, float, float] = (0.0, 0.0, 0.0)
    cpus: int = 0

    @property
    def speedup(self) -> float:
        return self.runs[-1].units_per_hour / self.runs[0].units_per_hour

    @property
    def identical(self) -> bool:
        return len({r.results_sha256 for r in self.runs}) == 1

    def to_dict(self) -> dict[str, Any]:
        return {
            "replicates": self.replicates,
            "group_size": self.group_size,
            "runs": [r.to_dict() for r in self.runs],
            "speedup": self.speedup,
            "identical_results": self.identical,
            "load_average": list(self.load_average),
            "cpus": self.cpus,
            "targets": {"speedup_2_workers": 1.8, "overhead": 0.05},
            "note": "simulated participants; the campaign's own figures are not measured data",
        }


def run_campaign_bench(
    replicates: int, group_size: int, workers: int, progress: Progress
) -> CampaignBench:
    # lazy: study.campaign.engine (with scipy, statsmodels, pandas) costs 1.8 s at start-up
    from study.campaign.engine import close_client, open_client, run_pending

    # lazy: study.campaign.spec (with numpy) costs 0.1 s at start-up
    from study.campaign.spec import parse_campaign

    # lazy: study.campaign.store (with scipy, statsmodels, pandas) costs 1.4 s at start-up
    from study.campaign.store import CampaignDir

    text = TOML.format(replicates=replicates, n=group_size)
    spec = parse_campaign(text, "bench")
    bench = CampaignBench(replicates, group_size, cpus=os.cpu_count() or 0)
    with tempfile.TemporaryDirectory() as tmp:
        for n in (1, workers):
            progress(f"starting a LocalCluster of {n} worker(s)")
            folder = CampaignDir.open(Path(tmp) / f"w{n}", spec, text)
            folder.create()
            client = open_client(n, None)
            try:
                from study.campaign.engine import WarmUp

                client.register_plugin(WarmUp(spec.task))  # warm before the clock starts
                client.wait_for_workers(n)
                done = 0

                def unit_done(_: str, n: int = n) -> None:
                    nonlocal done
                    done += 1
                    progress(f"{n} worker(s): {done} of {len(spec.units())} units")

                start = time.perf_counter()
                ran = run_pending(folder, client, on_unit=unit_done)
                wall = time.perf_counter() - start
            finally:
                close_client(client)
            folder.write_tables()
            digest = hashlib.sha256((folder.root / "results.csv").read_bytes()).hexdigest()
            seconds = [float(s) for s in folder.unit_times()]
            bench.runs.append(WorkerRun(n, ran, wall, seconds, digest))
    bench.load_average = os.getloadavg()
    return bench
