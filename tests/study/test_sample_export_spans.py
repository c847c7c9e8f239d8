"""`study export --samples` read in small spans by several threads: the same rows as the
database holds, in the same order, as one thread reading one span at a time writes.

The reference is the independent SQL join of `test_sample_export`.
"""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq
import pytest
from sqlalchemy.orm import Session

from db.migrate import open_database
from study.cli import main
from study.protocol.roster import load_study
from study.protocol.sample_export import (
    SampleSelection,
    select_trials,
    write_samples,
    write_samples_per_trial,
)
from tests.study.test_sample_export import _SIZES, _build_study, _read, _reference, _same


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_small_spans_on_three_threads_give_the_rows_the_database_holds(
    db_url: str, tmp_path: Path, fmt: str
) -> None:
    _build_study(db_url, tmp_path, _SIZES)
    engine = open_database(db_url, create=False)
    try:
        with Session(engine) as session:
            _, design = load_study(session)
            trials = select_trials(session, design, SampleSelection())
        path = tmp_path / f"samples.{fmt}"
        # 700-sample spans: the 2,500-sample trial is read in 4 windows, the others whole
        rows = write_samples(engine, trials, path, fmt, span_rows=700, workers=3)
        per_trial = write_samples_per_trial(
            engine, trials, tmp_path / "pt", fmt, span_rows=700, workers=3
        )
    finally:
        engine.dispose()
    want = _reference(db_url)
    assert rows == per_trial.rows == len(want) == 5100
    _same(_read(path), want)
    if fmt == "parquet":
        groups = pq.ParquetFile(path).metadata
        sizes = [groups.row_group(k).num_rows for k in range(groups.num_row_groups)]
        assert max(sizes) <= 700
        assert sum(sizes) == 5100
    # the per-trial files hold the same rows, trial by trial
    for trial in trials:
        got = _read(tmp_path / "pt" / f"{trial.file_stem}.{fmt}")
        mine = want[
            (want.participant == trial.participant)
            & (want.trial == trial.trial)
            & (want.condition == trial.condition)
        ]
        _same(got, mine)


def test_one_thread_and_four_write_the_same_bytes(sqlite_url: str, tmp_path: Path) -> None:
    _build_study(sqlite_url, tmp_path, _SIZES)
    argv = ["export", "--samples", "--db", sqlite_url, "--from-s", "0.2"]
    assert main([*argv, "--out", str(tmp_path / "one"), "--jobs", "1"]) == 0
    assert main([*argv, "--out", str(tmp_path / "four"), "--jobs", "4"]) == 0
    one = (tmp_path / "one" / "samples.csv").read_bytes()
    assert one == (tmp_path / "four" / "samples.csv").read_bytes()
    assert one.count(b"\n") == 1 + len(_reference(sqlite_url).query("t_s >= 0.2"))
