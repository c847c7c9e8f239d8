"""Running a campaign's units on Dask distributed, and nothing else.

Dask is the engine (the charter's distributed engine): an embedded `LocalCluster` of
`workers` single-threaded processes by default, or the scheduler at `scheduler`
(`tcp://HOST:PORT`, with workers started by `dask worker`, dask-jobqueue, ...), whose
workers must import this same `haptic-study`. Each pending unit is one task, keyed by
the campaign and the unit, so resubmitting it is idempotent. The client writes each
finished unit (`CampaignDir.save_unit`); a worker only computes. When a worker dies
mid-unit the scheduler gives that task to another worker (Dask's own recovery; a task
that has killed `distributed.scheduler.allowed-failures` workers is given up as
`KilledWorker`), so a lost worker costs that unit only.

Each worker warms up once (`WarmUp`: numba compiles the loop's kernel on the first
trial of a process, several seconds), so the first unit on a worker costs what the
others do and the benchmark's per-unit figures are the steady state.
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass

import pandas as pd
from distributed import Client, LocalCluster, WorkerPlugin, as_completed

from study.campaign.spec import CampaignSpec, Cell, unit_id
from study.campaign.store import CampaignDir
from study.campaign.unit import _estimator, run_unit
from study.errors import StudyInputError
from study.protocol.tasks import get_task
from study.protocol.traits import simulated_participant

CONNECT_TIMEOUT_S = 20.0
"""How long to wait for `--scheduler` before saying it cannot be reached."""


class WarmUp(WorkerPlugin):
    """Import the simulation and, for LCCA, compile the loop's kernel and load the
    estimator when a worker starts."""

    name = "haptic-study-warm-up"

    def __init__(self, task: str) -> None:
        self.task = task

    def setup(self, worker: object) -> None:
        warm_up(self.task)


def warm_up(task: str) -> None:
    """One second of a trial of `task` (LCCA: numba compiles the kernel)."""
    from study.protocol.trial_run import simulate_trial

    the_task = get_task(task)
    estimator = _estimator() if the_task.has_dial else None
    traits = simulated_participant("expert", 0)
    simulate_trial(the_task, traits, "HV", 0, 1.0, estimator=estimator)


def compute_unit(spec: CampaignSpec, cell: Cell, replicate: int) -> tuple[pd.DataFrame, float]:
    """The task a worker runs (a module-level function, so workers import it by name)."""

    return run_unit(spec, cell, replicate)


def campaign_key(spec: CampaignSpec) -> str:
    """A short digest of the campaign, prefixed to its tasks' keys."""
    text = json.dumps(spec.to_dict(), sort_keys=True).encode()
    return hashlib.sha256(text).hexdigest()[:12]


@dataclass
class RunInfo:
    dashboard: str | None
    """Dask's dashboard address."""
    workers: int
    pending: int
    """Units that were still to run."""


def open_client(workers: int | None, scheduler: str | None) -> Client:
    """A client on a new LocalCluster of `workers` processes, or on `scheduler`."""
    if scheduler is not None:
        if not scheduler.startswith(("tcp://", "tls://", "inproc://", "ws://", "wss://")):
            raise StudyInputError(
                f"--scheduler {scheduler!r}; expected an address like tcp://HOST:PORT"
            )
        try:
            return Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as exc:
            raise StudyInputError(
                f"--scheduler {scheduler}: no Dask scheduler answered ({type(exc).__name__}); "
                "expected the address `dask scheduler` printed"
            ) from None
    cluster = LocalCluster(
        n_workers=workers or 1,
        threads_per_worker=1,
        processes=True,
        dashboard_address="127.0.0.1:0",
        host="127.0.0.1",
        silence_logs=logging.ERROR,
    )
    client = Client(cluster)
    return client


def close_client(client: Client) -> None:
    """Close a client from `open_client` and the LocalCluster it started, if any (a
    scheduler of someone else's keeps running)."""
    cluster = client.cluster
    client.close()
    if cluster is not None:
        cluster.close()


def run_pending(
    folder: CampaignDir,
    client: Client,
    on_start: Callable[[RunInfo], None] = lambda _: None,
    on_unit: Callable[[str], None] = lambda _: None,
) -> int:
    """Run the folder's pending units on `client`, saving each as it finishes; return
    how many ran. Interrupting (Ctrl-C, kill) keeps every unit saved so far."""
    pending = folder.pending()
    client.register_plugin(WarmUp(folder.spec.task))
    if client.cluster is None:  # an external scheduler: wait for at least one worker
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S * 3)
    info = RunInfo(client.dashboard_link, len(client.scheduler_info()["workers"]), len(pending))
    on_start(info)
    if not pending:
        return 0
    prefix = campaign_key(folder.spec)
    futures = {}
    for k, (cell, replicate) in enumerate(pending):
        future = client.submit(
            compute_unit,
            folder.spec,
            cell,
            replicate,
            key=f"campaign-{prefix}-{unit_id(cell, replicate)}",
            pure=False,
            priority=-k,  # grid order first, so a stopped run leaves a prefix done
        )
        futures[future.key] = (future, cell, replicate)
    done = 0
    for future in as_completed([f for f, _, _ in futures.values()]):
        _, cell, replicate = futures.pop(future.key)
        rows, seconds = future.result()
        folder.save_unit(cell, replicate, rows, seconds)
        future.release()
        done += 1
        on_unit(unit_id(cell, replicate))
    return done
