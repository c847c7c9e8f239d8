"""The sample writer under another program's lock: samples held in memory, none lost."""

from __future__ import annotations

import itertools
import subprocess
import sys
from collections.abc import Iterator

import numpy as np
import pytest
from sqlalchemy import Engine, select
from sqlalchemy.exc import OperationalError

from db.migrate import open_database
from db.models import SampleChunk
from db.sample_reader import SampleReader
from db.samples import SampleWriter
from tests.db.test_samples import SCHEMA, _stored, _trial


@pytest.fixture
def sqlite_engine(tmp_path) -> Iterator[Engine]:
    # busy timeout 0.3 s: a commit that waits for the lock gives up quickly
    eng = open_database(f"sqlite:///{tmp_path / 'study.db'}?timeout=0.3")
    try:
        yield eng
    finally:
        eng.dispose()


class Locker:
    """Another process holding `BEGIN EXCLUSIVE` on the database until released."""

    def __init__(self, path: str) -> None:
        code = (
            "import sqlite3, sys\n"
            f"db = sqlite3.connect({path!r}, isolation_level=None)\n"
            "db.execute('BEGIN EXCLUSIVE'); print('locked', flush=True)\n"
            "sys.stdin.readline(); db.execute('ROLLBACK'); db.close()\n"
            "print('released', flush=True)\n"
        )
        self.process = subprocess.Popen(
            [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        assert self.process.stdout.readline().strip() == "locked"

    def release(self) -> None:
        self.process.stdin.write("\n")
        self.process.stdin.flush()
        assert self.process.stdout.readline().strip() == "released"
        self.process.wait()


def _columns(t: np.ndarray) -> dict[str, np.ndarray]:
    return {"t_s": t, "proximal_force_n": np.sin(t)}


def test_a_lock_during_the_trial_holds_the_samples_and_commits_them_after(
    sqlite_engine: Engine,
) -> None:
    trial_id = _trial(sqlite_engine)
    waits: list[tuple[float | None, int]] = []
    writer = SampleWriter(
        sqlite_engine,
        trial_id,
        schema=SCHEMA,
        hold_s=60.0,
        on_wait=lambda s, n: waits.append((s, n)),
    )
    t = np.arange(1000) / 100.0  # 10 s at 100 Hz, handed in 0.5 s steps
    writer.extend(_columns(t[:150]))  # 1.5 s: committed (the writer commits ahead)
    before = _stored(sqlite_engine, trial_id)
    assert before >= 100
    locker = Locker(sqlite_engine.url.database)
    try:
        for k in range(150, 800, 50):  # 6.5 s more while locked: no error, held
            writer.extend(_columns(t[k : k + 50]))
        assert _stored(sqlite_engine, trial_id) == before  # nothing could be written
        assert writer.waiting_since is not None
        held = [n for s, n in waits if s is not None]
        # more and more held: every chunk encoded since the lock, none dropped
        assert held == sorted(held)
        assert held[-1] == writer.next_seq - before >= 500
    finally:
        locker.release()
    writer.extend(_columns(t[800:]))
    writer.close()
    assert waits[-1] == (None, 0)  # the wait ended, said once
    # every sample, in order, once: the stored stream is the one handed in
    with SampleReader(sqlite_engine) as reader:
        stored = np.concatenate([b.column("t_s").to_numpy() for b in reader.trial(trial_id)])
    np.testing.assert_array_equal(stored, t)
    with sqlite_engine.connect() as conn:
        seqs = conn.execute(
            select(SampleChunk.first_seq, SampleChunk.n_samples).order_by(SampleChunk.first_seq)
        ).all()
    assert all(a + n == b for (a, n), (b, _) in itertools.pairwise(seqs))


def test_past_its_hold_the_writer_waits_then_raises_and_keeps_what_it_had(
    sqlite_engine: Engine,
) -> None:
    trial_id = _trial(sqlite_engine)
    writer = SampleWriter(sqlite_engine, trial_id, schema=SCHEMA, hold_s=2.0)
    t = np.arange(600) / 100.0
    locker = Locker(sqlite_engine.url.database)
    try:
        with pytest.raises(OperationalError, match="locked"):
            for k in range(0, 600, 50):
                writer.extend(_columns(t[k : k + 50]))
    finally:
        locker.release()
    assert writer.held_samples() > 200  # held, not dropped: a later flush commits them
    writer.close()
    assert _stored(sqlite_engine, trial_id) == writer.next_seq
