"""Helpers the `study` tests share (the database fixtures are in tests/conftest.py)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any


def modules_loaded(code: str, prefixes: tuple[str, ...]) -> list[str]:
    """The modules named by `prefixes` (and their submodules) that a fresh interpreter has
    loaded after running `code`: what a command or screen costs at its start."""
    probe = (
        f"{code}\nimport json, sys\n"
        f"print(json.dumps(sorted(m for m in sys.modules if m.startswith({prefixes!r}))))"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def init_study(folder: Path, design: str | None = None, groups: tuple[str, ...] = ()) -> str:
    """`study init` of a database folder/s.db from `design` (written to folder/d.toml; the
    template by default), then `study participant add` for each of `groups`: its path."""
    from study.cli import main
    from study.protocol.design import TEMPLATE

    db = str(folder / "s.db")
    (folder / "d.toml").write_text(TEMPLATE if design is None else design)
    assert main(["init", "--design", str(folder / "d.toml"), "--db", db]) == 0
    for group in groups:
        assert main(["participant", "add", "--group", group, "--db", db]) == 0
    return db


def stored_samples(trial_id: Any) -> Any:
    """A query of how many samples trial `trial_id` (a value or a column) has stored."""
    from sqlalchemy import func, select

    from db.models.trial import SampleChunk

    chunk = SampleChunk
    return select(func.coalesce(func.sum(chunk.n_samples), 0)).where(chunk.trial_id == trial_id)


def last_sample_s(trial_id: Any) -> Any:
    """A query of the time of trial `trial_id`'s last stored sample, s (None if none)."""
    from sqlalchemy import func, select

    from db.models.trial import SampleChunk

    return select(func.max(SampleChunk.t_last_s)).where(SampleChunk.trial_id == trial_id)


def samples_of_trial() -> Any:
    """A scalar subquery for a query over Trial rows: how many samples the trial has."""
    from db.models.trial import Trial

    return stored_samples(Trial.id).scalar_subquery()


def one_error_line(capsys: Any, argv: list[str]) -> str:
    """Run `study ARGV`, which must fail as a usage error (2) with one line on stderr: it."""
    from study.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def assert_workers_end(workers: list[int], timeout_s: float) -> None:
    """Wait up to `timeout_s` for the processes `workers` to end; fail if one is left."""
    import time

    from study.protocol.lease import process_alive

    deadline = time.monotonic() + timeout_s
    while any(process_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(process_alive(w) for w in workers), "workers outlived their parent"


def assert_figures(folder: Path, *names: str) -> None:
    """Each figure file is in `folder` and is a real picture (over 10 kB)."""
    small = {n: (folder / n).stat().st_size for n in names if (folder / n).stat().st_size <= 10_000}
    assert not small, f"figures of 10 kB or less: {small}"
