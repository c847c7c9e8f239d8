"""The sample write path: chunked commits, values kept exactly, bad samples refused."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from sqlalchemy import Engine, func, select

from db.engine import make_session_factory
from db.errors import DbInputError
from db.models import Participant, SampleChunk, Study, Trial
from db.sample_reader import SampleReader
from db.samples import SampleWriter
from study.protocol.tasks import get_task

SCHEMA = get_task("lcca").sample_schema()
"""The schema the samples of `_trial`'s trial (an LCCA trial) are stored in."""


def _trial(engine: Engine) -> int:
    with make_session_factory(engine).begin() as session:
        study = Study(name="s", design_toml="", design={}, seed=1)
        p = Participant(study=study, code="P001", group="expert", condition_order=["HV", "VO"])
        trial = Trial(participant=p, task="lcca", condition="HV", block_index=0, trial_index=0)
        session.add(trial)
        session.flush()
        return trial.id


def _stored(engine: Engine, trial_id: int) -> int:
    with engine.connect() as conn:
        n = select(func.sum(SampleChunk.n_samples)).where(SampleChunk.trial_id == trial_id)
        return conn.scalar(n) or 0


def test_commits_one_chunk_per_second_of_trial_time(engine: Engine) -> None:
    trial_id = _trial(engine)
    t = np.arange(3500) / 1000.0  # 3.5 s at 1 kHz
    writer = SampleWriter(engine, trial_id, schema=SCHEMA, chunk_s=1.0)
    writer.extend({"t_s": t[:1500], "proximal_force_n": np.full(1500, 0.25)})
    # [0, 1) s and [1, 1.5) s are committed: holding [1, 1.5) s while the caller computes
    # its next 1.5 s step would put 2 s at risk.
    assert (writer.rows_committed, writer.chunks_committed) == (1500, 2)
    assert _stored(engine, trial_id) == 1500
    writer.extend({"t_s": t[1500:], "proximal_force_n": np.full(2000, 0.25)})
    # [1.5, 2.5) and [2.5, 3.5) s: no chunk spans more than one second
    assert (writer.rows_committed, writer.chunks_committed) == (3500, 4)
    writer.close()
    assert (_stored(engine, trial_id), writer.chunks_committed) == (3500, 4)


def test_one_connection_for_the_writers_life_given_back_at_close(engine: Engine) -> None:
    """Ten chunks take one connection from the pool (not one each) and it is back in the
    pool after close."""
    from sqlalchemy import event

    trial_id = _trial(engine)
    checkouts: list[int] = []

    def _checkout(*_args: object) -> None:
        checkouts.append(1)

    writer = SampleWriter(engine, trial_id, schema=SCHEMA, chunk_s=1.0)
    writer.__enter__()  # the schema's row: its own short transaction
    event.listen(engine, "checkout", _checkout)
    try:
        t = np.arange(1000) / 100.0  # 10 s at 100 Hz in 0.5 s steps: 10 chunks
        for k in range(0, 1000, 50):
            writer.extend({"t_s": t[k : k + 50], "proximal_force_n": np.full(50, 0.5)})
        writer.__exit__(None, None, None)
    finally:
        event.remove(engine, "checkout", _checkout)
    assert writer.chunks_committed == 10
    assert _stored(engine, trial_id) == 1000
    assert len(checkouts) == 1
    assert engine.pool.checkedout() == 0


@pytest.mark.parametrize("step_s", [0.05, 0.25, 0.5, 0.7, 1.0, 2.5])
def test_held_plus_the_next_step_never_exceeds_one_second(engine: Engine, step_s: float) -> None:
    """A crash loses what the writer holds plus the step being computed (0.5 s
    steps used to put 1.5 s at risk)."""
    trial_id = _trial(engine)
    per_step = round(step_s * 100)  # 100 Hz, as the loops sample
    handed = 0
    with SampleWriter(engine, trial_id, schema=SCHEMA, chunk_s=1.0) as writer:
        for _ in range(round(6 / step_s)):
            t = (handed + np.arange(per_step)) / 100
            writer.extend({"t_s": t})
            handed += per_step
            held = handed - writer.rows_committed
            # at risk if killed during the next step: the samples held and the next step's
            assert held + min(per_step, 100) <= 100 or held == 0
    assert _stored(engine, trial_id) == handed


def test_single_appends_follow_the_same_chunking(engine: Engine) -> None:
    trial_id = _trial(engine)
    with SampleWriter(engine, trial_id, schema=SCHEMA, chunk_s=0.5) as writer:
        for k in range(250):  # 2.5 s at 100 Hz
            writer.append(t_s=k / 100, distal_force_n=0.01 * k)
            # Never more than half a second of samples unsaved.
            assert (k + 1) - writer.rows_committed <= 50
    assert writer.chunks_committed == 5
    assert _stored(engine, trial_id) == 250


def test_values_round_trip_exactly_with_nulls_for_missing_columns(engine: Engine) -> None:
    trial_id = _trial(engine)
    rng = np.random.default_rng(3)
    force = rng.normal(0.3, 0.1, 20)
    with SampleWriter(engine, trial_id, schema=SCHEMA, start_seq=100) as writer:
        writer.extend(
            {
                "t_s": np.arange(20) / 100,
                "proximal_force_n": force,
                "branch": ["arch"] * 10 + ["lcca"] * 10,
            }
        )
    with SampleReader(engine) as reader:
        rows = [
            SimpleNamespace(**row) for batch in reader.trial(trial_id) for row in batch.to_pylist()
        ]
    assert [r.seq for r in rows] == list(range(100, 120))
    assert [r.proximal_force_n for r in rows] == force.tolist()  # bit-exact doubles
    assert [r.branch for r in rows] == ["arch"] * 10 + ["lcca"] * 10
    assert all(r.distal_force_n is None for r in rows)
    assert math.isclose(rows[-1].t_s, 0.19)


@pytest.mark.parametrize(
    ("columns", "message"),
    [
        ({"t_s": [0.0, 0.02, 0.01]}, r"t_s=0.01 at sample 2 goes back in time"),
        ({"t_s": [0.0, float("nan")]}, r"t_s=nan at sample 1 is not a finite"),
        ({"t_s": [0.0], "force": [1.0]}, r"must include 't_s' and only names"),
        ({"proximal_force_n": [1.0]}, r"must include 't_s'"),
        (
            {"t_s": [0.0, 0.1], "distal_force_n": [1.0]},
            r"'distal_force_n' has 1 values; expected 2",
        ),
        (
            {"t_s": [0.0, 0.1], "distal_force_n": [1.0, "heavy"]},
            r"column 'distal_force_n' has a value that is not a number \(.*'heavy'",
        ),
        (
            {"t_s": [0.0, 0.1], "branch": ["arch", 3]},
            r"column 'branch' has a value that is not text \(a branch name\) or None",
        ),
    ],
)
def test_bad_samples_are_refused_without_writing_them(
    engine: Engine, columns: dict[str, list[float]], message: str
) -> None:
    trial_id = _trial(engine)
    writer = SampleWriter(engine, trial_id, schema=SCHEMA)
    with pytest.raises(DbInputError, match=message):
        writer.extend(columns)
    writer.close()
    assert _stored(engine, trial_id) == 0


def test_time_must_not_go_back_across_calls(engine: Engine) -> None:
    trial_id = _trial(engine)
    with SampleWriter(engine, trial_id, schema=SCHEMA) as writer:
        writer.extend({"t_s": [0.0, 0.5]})
        with pytest.raises(DbInputError, match=r"t_s=0\.4 at sample 2 goes back"):
            writer.append(t_s=0.4)
    assert _stored(engine, trial_id) == 2


_WRITE_THEN_DIE = """
import os, signal, sys
import numpy as np
from db.migrate import open_database
from db.sample_reader import SampleReader
from db.samples import SampleWriter
from study.protocol.tasks import get_task
engine = open_database(sys.argv[1])
schema = get_task("lcca").sample_schema()
writer = SampleWriter(engine, int(sys.argv[2]), schema=schema, chunk_s=1.0)
for k in range(2600):  # 2.6 s at 1 kHz, one sample at a time as a live session does
    writer.append(t_s=k / 1000, proximal_force_n=0.5)
print(writer.rows_committed, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_kill_9_loses_at_most_the_last_chunk(engine: Engine, db_url: str) -> None:
    trial_id = _trial(engine)
    proc = subprocess.run(
        [sys.executable, "-c", _WRITE_THEN_DIE, db_url, str(trial_id)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == -signal.SIGKILL
    committed = int(proc.stdout.strip())
    assert committed == 2000  # chunks [0, 1) and [1, 2) s
    assert _stored(engine, trial_id) == committed
    with engine.connect() as conn:
        last_t = conn.scalar(
            select(func.max(SampleChunk.t_last_s)).where(SampleChunk.trial_id == trial_id)
        )
    assert 2.599 - last_t <= 1.0  # lost: under one second of samples
