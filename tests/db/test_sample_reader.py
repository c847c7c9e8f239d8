"""Reading many trials in spans (`db.sample_reader`): bounded spans, every sample once,
in trial and `seq` order, whatever the number of threads.

Expected spans are worked out by hand from the trials' sizes; the expected rows from
the values written (sample k of trial i: seq k, t_s = k / 1000, distal = i + t_s).
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pyarrow as pa
import pytest
from sqlalchemy import Engine

from db.engine import make_session_factory
from db.errors import DbInputError
from db.models import Participant, Study, Trial
from db.sample_reader import SampleSpan, plan_spans, read_spans, span_schema
from db.samples import SampleWriter
from tests.db.test_samples import SCHEMA


def _trials(engine: Engine, sizes: list[int], start_seq: int = 0) -> list[int]:
    """One trial per size, `size` samples each (seq from `start_seq`); their ids."""
    with make_session_factory(engine).begin() as session:
        study = Study(name="s", design_toml="", design={}, seed=1)
        p = Participant(study=study, code="P001", group="expert", condition_order=["HV", "VO"])
        trials = [
            Trial(participant=p, task="lcca", condition="HV", block_index=0, trial_index=k)
            for k in range(len(sizes))
        ]
        session.add_all(trials)
        session.flush()
        ids = [t.id for t in trials]
    for trial_id, n in zip(ids, sizes, strict=True):
        with SampleWriter(engine, trial_id, schema=SCHEMA, start_seq=start_seq) as writer:
            t = np.arange(n) / 1000.0
            writer.extend({"t_s": t, "distal_force_n": trial_id + t})
    return ids


def test_spans_join_small_trials_and_cut_long_ones(engine: Engine) -> None:
    a, b, c, d, e, f = _trials(engine, [2500, 300, 400, 200, 0, 1000], start_seq=10)
    plan = plan_spans(engine, [a, b, c, d, e, f], max_rows=1000)
    # a: seq 10..2509 in windows of 1000; b, c, d: 900 samples together, listed under b;
    # e has none; f (1000) would make b+c+d 1900, so it starts its own span.
    assert plan == [
        [
            SampleSpan((a,), 10, 1010, 1000),
            SampleSpan((a,), 1010, 2010, 1000),
            SampleSpan((a,), 2010, 3010, 1000),
        ],
        [SampleSpan((b, c, d), rows=900)],
        [],
        [],
        [],
        [SampleSpan((f,), rows=1000)],
    ]
    # one file per trial: nothing joined
    assert plan_spans(engine, [b, c], max_rows=1000, join_trials=False) == [
        [SampleSpan((b,), rows=300)],
        [SampleSpan((c,), rows=400)],
    ]
    # trials out of id order are never joined (a span reads in id order)
    assert plan_spans(engine, [c, b], max_rows=1000) == [
        [SampleSpan((c,), rows=400)],
        [SampleSpan((b,), rows=300)],
    ]
    with pytest.raises(DbInputError, match="max_rows 0"):
        plan_spans(engine, [a], max_rows=0)


@pytest.mark.parametrize("workers", [1, 3])
def test_spans_read_every_sample_once_in_order(engine: Engine, workers: int) -> None:
    sizes = [2500, 300, 400, 200, 0, 1000, 1]
    ids = _trials(engine, sizes)
    want = [
        (i, k, k / 1000.0, i + k / 1000.0)
        for i, n in zip(ids, sizes, strict=True)
        for k in range(n)
        if 0.1 <= k / 1000.0 < 2.2
    ]
    spans = [s for per_trial in plan_spans(engine, ids, max_rows=700) for s in per_trial]
    tables = list(
        read_spans(engine, spans, lambda span, table: table, workers=workers, from_s=0.1, to_s=2.2)
    )
    assert all(t.schema.equals(span_schema(SCHEMA)) for t in tables)
    assert max(t.num_rows for t in tables) <= 700
    got = pa.concat_tables(tables)
    assert len(got) == len(want) == sum(min(n, 2200) - min(n, 100) for n in sizes)
    for k, name in enumerate(["trial_id", "seq", "t_s", "distal_force_n"]):
        np.testing.assert_array_equal(got.column(name).to_numpy(), [row[k] for row in want])


def test_at_most_workers_plus_one_spans_are_read_ahead(engine: Engine) -> None:
    """A slow consumer never has more than workers + 1 spans read and waiting."""
    ids = _trials(engine, [50] * 12)
    spans = [s for p in plan_spans(engine, ids, max_rows=50) for s in p]
    started: list[int] = []
    lock = threading.Lock()

    def work(span: SampleSpan, table: pa.Table) -> int:
        with lock:
            started.append(span.trial_ids[0])
        time.sleep(0.01 * (span.trial_ids[0] % 3))  # finish out of order
        return span.trial_ids[0]

    seen = []
    for trial_id in read_spans(engine, spans, work, workers=2):
        time.sleep(0.02)  # a slow writer
        with lock:
            ahead = len(started) - len(seen)
        assert ahead <= 3, (started, seen)
        seen.append(trial_id)
    assert seen == ids


def test_an_error_in_a_span_reaches_the_caller_and_stops_the_rest(engine: Engine) -> None:
    ids = _trials(engine, [20] * 8)
    spans = [s for p in plan_spans(engine, ids, max_rows=20) for s in p]
    done: list[int] = []

    def work(span: SampleSpan, table: pa.Table) -> int:
        if span.trial_ids[0] == ids[2]:
            raise ValueError("bad span")
        done.append(span.trial_ids[0])
        return table.num_rows

    with pytest.raises(ValueError, match="bad span"):
        list(read_spans(engine, spans, work, workers=2))
    assert len(done) <= 2 + 3  # the spans before it, and at most the read-ahead
    with pytest.raises(DbInputError, match="workers 0"):
        next(read_spans(engine, spans, work, workers=0))


def test_the_reader_waits_for_a_lock_as_the_study_connections_do(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Its SQLite connection has the URL's busy timeout (`?timeout=7`: 7,000 ms), as
    every study connection (two reader threads opening together had got "database is
    locked" when the reader had its own driver's default of 0)."""
    from db.migrate import open_database
    from db.sample_reader import SampleReader

    engine = open_database(f"sqlite:///{tmp_path / 's.db'}?timeout=7")
    try:
        with SampleReader(engine) as reader:
            assert reader._conn.exec_driver_sql("PRAGMA busy_timeout").all() == [(7000,)]
    finally:
        engine.dispose()


def test_a_span_that_reads_nothing_has_its_trials_stored_columns(engine: Engine) -> None:
    """An empty span's table has the columns of its trials' stored schema (the LCCA
    task's names here), or `t_s` alone for trials without samples."""
    from db.sample_reader import SampleReader

    lcca, empty = _trials(engine, [100, 0])
    with SampleReader(engine) as reader:
        late = reader.span(SampleSpan((lcca,)), from_s=5.0)
        none = reader.span(SampleSpan((empty,)))
    assert late.num_rows == 0
    assert late.column_names == [
        "trial_id",
        "seq",
        "t_s",
        "insertion_m",
        "rotation_rad",
        "tip_x_m",
        "tip_y_m",
        "tip_z_m",
        "branch",
        "reference_force_n",
        "proximal_force_n",
        "distal_force_n",
        "dial_angle_rad",
        "dial_torque_n_m",
    ]
    assert (none.num_rows, none.column_names) == (0, ["trial_id", "seq", "t_s"])
