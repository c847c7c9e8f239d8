"""`study export --samples`: streamed in bounded memory, same rows as the database holds.

The reference for every comparison is read independently of the code under test: a
plain DBAPI connection (sqlite3 or psycopg), one SQL join written here, each stored
chunk decoded with pyarrow as `db.sample_codec`'s description of the format says (the
schema written out here), and pandas.
"""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import psycopg
import pyarrow.parquet as pq
import pytest
from sqlalchemy.engine import make_url

from db.engine import make_session_factory
from db.migrate import open_database
from db.models import Participant, Trial
from db.sample_reader import SampleReader
from db.samples import SampleWriter
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.export import export_data
from study.protocol.tasks import get_task
from tests.conftest import decode_stored_chunk

LCCA_COLUMNS = (
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
)
"""The LCCA task's own sample columns, written out here."""
SAMPLE_EXPORT_COLUMNS = ("participant", "task", "condition", "trial", "seq", *LCCA_COLUMNS)
LCCA_SCHEMA = get_task("lcca").sample_schema()
"""The trials here are written in the LCCA's own schema, as the session writes them."""

_REFERENCE_SQL = """
SELECT p.code, t.task, t.condition, t.trial_index + 1, c.first_seq, c.raw_bytes, c.data,
       s.data
FROM sample_chunks c JOIN trials t ON c.trial_id = t.id
JOIN sample_schemas s ON s.id = c.schema_id
JOIN participants p ON t.participant_id = p.id
WHERE t.status = 'completed' AND NOT t.practice
ORDER BY t.id, c.first_seq
"""


def _columns(rng: np.random.Generator, n: int, start_null: bool) -> dict[str, object]:
    t = np.cumsum(rng.uniform(0.0005, 0.0015, n))
    branch = rng.choice(np.array(["DAo", "arch", "LCCA"], dtype=object), n)
    distal = rng.normal(0, 1e-3, n).astype(object)
    if start_null:
        # NULLs first: the SQLite driver would type these columns from the first batch.
        branch[: n // 2] = None
        distal[: n // 2] = None
    return {
        "t_s": t,
        "insertion_m": rng.uniform(0, 0.3, n),
        "rotation_rad": rng.normal(0, 3, n),
        "branch": branch,
        "reference_force_n": np.abs(rng.normal(0.5, 0.2, n)),
        "proximal_force_n": np.round(rng.normal(0.5, 0.2, n), 1),  # 1.0, 0.1, ...
        "distal_force_n": distal,
        "dial_angle_rad": rng.normal(0, 1e-300, n),
        # tip_* and dial_torque_n_m stay NULL, as for a task that does not produce them.
    }


def _build_study(db: str, tmp_path: Path, sizes: dict[tuple[str, str, int], int]) -> None:
    """Study with TEMPLATE's design; `sizes[(code, condition, trial)]` samples each,
    plus a practice trial and an interrupted one whose samples must not be exported."""
    (tmp_path / "d.toml").write_text(TEMPLATE)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    engine = open_database(db, create=False)
    rng = np.random.default_rng(7)
    try:
        with make_session_factory(engine).begin() as session:
            from db.models import Study

            study = session.query(Study).one()
            people = {
                code: Participant(
                    study=study, code=code, group="novice", condition_order=["VO", "HV"]
                )
                for code in sorted({c for c, _, _ in sizes})
            }
            trials = {}
            for (code, cond, number), _ in sizes.items():
                trials[(code, cond, number)] = Trial(
                    participant=people[code],
                    task="lcca",
                    condition=cond,
                    block_index=["VO", "HV"].index(cond),
                    trial_index=number - 1,
                    status="completed",
                    practice=False,
                )
            extra = [
                Trial(
                    participant=people["P001"],
                    task="lcca",
                    condition="VO",
                    block_index=0,
                    trial_index=0,
                    practice=True,
                    status="completed",
                ),
                Trial(
                    participant=people["P001"],
                    task="lcca",
                    condition="HV",
                    block_index=1,
                    trial_index=2,
                    status="interrupted",
                ),
            ]
            session.add_all([*trials.values(), *extra])
            session.flush()
            ids = {k: t.id for k, t in trials.items()}
            extra_ids = [t.id for t in extra]
        for key, n in sizes.items():
            with SampleWriter(engine, ids[key], schema=LCCA_SCHEMA) as writer:
                writer.extend(_columns(rng, n, start_null=key[2] == 1))
        for trial_id in extra_ids:
            with SampleWriter(engine, trial_id, schema=LCCA_SCHEMA) as writer:
                writer.extend(_columns(rng, 50, start_null=False))
    finally:
        engine.dispose()


_SIZES = {
    ("P001", "VO", 1): 2500,
    ("P001", "HV", 2): 900,
    ("P002", "HV", 1): 1700,
    ("P002", "VO", 3): 0,
}


def _reference(db: str) -> pd.DataFrame:
    """The rows as plain sqlite3 / psycopg and pandas read them."""
    url = make_url(db)
    if url.get_backend_name() == "sqlite":
        conn = sqlite3.connect(url.database)
        cursor = conn.execute(_REFERENCE_SQL)
    else:
        options = url.query["options"]
        conn = psycopg.connect(
            host=url.host, port=url.port, user=url.username, dbname=url.database, options=options
        )
        cursor = conn.execute(_REFERENCE_SQL)
    frames = []
    for code, task, condition, trial, first_seq, raw_bytes, data, schema in cursor.fetchall():
        chunk = decode_stored_chunk(data, raw_bytes, schema).to_pandas()
        key = {"participant": code, "task": task, "condition": condition, "trial": trial}
        key["seq"] = first_seq + np.arange(len(chunk))
        frames.append(pd.concat([pd.DataFrame(key), chunk], axis=1))
    conn.close()
    frame = pd.concat(frames, ignore_index=True)
    return _norm(frame[list(SAMPLE_EXPORT_COLUMNS)])


def _read(path: Path) -> pd.DataFrame:
    if path.suffix == ".csv":
        frame = pd.read_csv(
            path,
            dtype={"branch": object},
            keep_default_na=False,
            na_values={c: [""] for c in SAMPLE_EXPORT_COLUMNS},
        )
    else:
        frame = pd.read_parquet(path)
    return _norm(frame)


def _norm(frame: pd.DataFrame) -> pd.DataFrame:
    """Text as Python str or None, numbers as int64/float64 (NaN for NULL)."""
    frame = frame.reset_index(drop=True).copy()
    for c in ("participant", "task", "condition", "branch"):
        frame[c] = pd.Series([v if isinstance(v, str) else None for v in frame[c]], dtype=object)
    for c in LCCA_COLUMNS:
        if c != "branch":
            frame[c] = frame[c].astype(float)
    return frame.astype({"trial": "int64", "seq": "int64"})


def _same(got: pd.DataFrame, want: pd.DataFrame) -> None:
    pd.testing.assert_frame_equal(_norm(got), _norm(want), check_exact=True)


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_export_equals_the_rows_the_database_holds(db_url: str, tmp_path: Path, fmt: str) -> None:
    _build_study(db_url, tmp_path, _SIZES)
    out = tmp_path / "out"
    assert main(["export", "--out", str(out), "--samples", "--format", fmt, "--db", db_url]) == 0
    path = out / f"samples.{fmt}"
    if fmt == "csv":
        assert path.read_text().splitlines()[0] == ",".join(SAMPLE_EXPORT_COLUMNS)
    else:
        assert pq.read_schema(path).names == list(SAMPLE_EXPORT_COLUMNS)
    want = _reference(db_url)
    assert len(want) == 2500 + 900 + 1700  # practice and interrupted trials left out
    _same(_read(path), want)
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["trials." + fmt, "tlx." + fmt, "samples." + fmt, "codebook.csv"]
    )  # no .partial file left


def test_selection_keeps_the_named_trials_and_time_range(db_url: str, tmp_path: Path) -> None:
    _build_study(db_url, tmp_path, _SIZES)
    out = tmp_path / "sel"
    argv = ["export", "--out", str(out), "--samples", "--format", "parquet", "--db", db_url]
    sel = ["--participant", "P001", "--condition", "VO", "--condition", "HV", "--task", "lcca"]
    assert main([*argv, *sel, "--trial", "1", "--from-s", "0.5", "--to-s", "1.25"]) == 0
    want = _reference(db_url)
    want = want[
        (want.participant == "P001") & (want.trial == 1) & (want.t_s >= 0.5) & (want.t_s < 1.25)
    ]
    assert 0 < len(want) < 2500
    _same(_read(out / "samples.parquet"), want)


def test_reader_yields_bounded_batches_that_add_up_to_the_trial(
    db_url: str, tmp_path: Path
) -> None:
    _build_study(db_url, tmp_path, _SIZES)
    want = _reference(db_url)
    engine = open_database(db_url, create=False)
    try:
        with make_session_factory(engine)() as session:
            trial_id = (
                session.query(Trial.id)
                .filter_by(condition="VO", trial_index=0, practice=False)
                .scalar()
            )
        with SampleReader(engine, batch_rows=300) as reader:
            batches = list(reader.trial(trial_id))
    finally:
        engine.dispose()
    assert max(b.num_rows for b in batches) <= 300
    assert len(batches) >= 2500 / 300
    got = pd.concat([b.to_pandas() for b in batches], ignore_index=True)
    ref = want[(want.participant == "P001") & (want.condition == "VO")]
    assert len(got) == len(ref) == 2500
    np.testing.assert_array_equal(got["t_s"], ref["t_s"])
    np.testing.assert_array_equal(got["seq"], np.arange(2500))


def test_per_trial_export_resumes_and_matches_the_single_file(
    sqlite_url: str, tmp_path: Path
) -> None:
    _build_study(sqlite_url, tmp_path, _SIZES)
    out = tmp_path / "pt"
    argv = ["export", "--out", str(out), "--samples", "--per-trial", "--db", sqlite_url]
    assert main(argv) == 0
    files = sorted((out / "samples").iterdir())
    assert [f.name for f in files] == [
        "P001_lcca_HV_trial2.csv",
        "P001_lcca_VO_trial1.csv",
        "P002_lcca_HV_trial1.csv",
        "P002_lcca_VO_trial3.csv",
    ]
    # An interrupted run leaves complete files only; the rerun writes the missing one.
    kept = files[0].stat().st_mtime_ns
    files[1].unlink()
    assert main(argv) == 0
    assert files[0].stat().st_mtime_ns == kept
    assert files[1].exists()
    got = pd.concat([_read(f) for f in files]).sort_values(["participant", "condition", "seq"])
    want = _reference(sqlite_url).sort_values(["participant", "condition", "seq"])
    _same(got, want)


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--participant", "P099"], "unknown participant 'P099'"),
        (["--task", "notes"], "task 'notes'; expected one of lcca"),
        (["--condition", "XX"], "condition 'XX'; expected one of VO, HV"),
        (["--from-s", "2", "--to-s", "1"], "time range from 2 s to 1 s is empty"),
    ],
)
def test_a_bad_selection_is_named_and_nothing_is_written(
    extra: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = str(tmp_path / "s.db")
    _build_study(db, tmp_path, {("P001", "VO", 1): 10})
    capsys.readouterr()
    out = tmp_path / "bad"
    assert main(["export", "--out", str(out), "--samples", *extra, "--db", db]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert message in err[0]
    assert not out.exists() or not any(out.iterdir())


def test_a_failed_export_leaves_no_file(tmp_path: Path) -> None:
    """The samples file fails mid-way (the database vanishes under the reader): no
    samples, trials or codebook file appears, and no partial file stays."""
    db = str(tmp_path / "s.db")
    _build_study(db, tmp_path, {("P001", "VO", 1): 10})
    out = tmp_path / "gone"
    sqlite3.connect(db).execute("DROP TABLE sample_chunks").connection.close()
    engine = open_database(db, create=False)
    try:
        with pytest.raises(Exception, match="no such table: sample_chunks"):
            export_data(engine, out, "parquet", samples=True)
    finally:
        engine.dispose()
    assert list(out.iterdir()) == []


_MEMORY_PROBE = """
import json, resource, sys
from pathlib import Path
from db.migrate import open_database
from study.protocol.export import export_data
engine = open_database(sys.argv[1], create=False)
out = Path(sys.argv[2])
export_data(engine, out / "warm", "parquet", samples=False)  # imports, caches
peaks = [resource.getrusage(resource.RUSAGE_SELF).ru_maxrss]
for fmt in ("csv", "parquet"):
    export_data(engine, out / fmt, fmt, samples=True)
    peaks.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
print(json.dumps(peaks))
"""


def test_export_memory_does_not_grow_with_the_samples(tmp_path: Path) -> None:
    """1,600,000 samples, about 160 MB as Arrow columns (and some 3 GB the way the export
    held them before): exporting them to CSV, then Parquet, raises the process's peak
    memory by less than half of that. What it may hold is a few spans in flight (the
    reader threads' tables, CSV text, the Parquet row group being encoded and the
    allocator's cache: 30-50 MB measured, the same for 400,000 and 1,200,000 samples)."""
    db = str(tmp_path / "big.db")
    _build_study(
        db,
        tmp_path,
        {("P001", "VO", k): 100_000 for k in (1, 2, 3)}
        | {(f"P{p:03d}", "HV", 1): 100_000 for p in range(2, 15)},
    )
    probe = subprocess.run(
        [sys.executable, "-c", _MEMORY_PROBE, db, str(tmp_path / "mem")],
        capture_output=True,
        text=True,
        check=True,
    )
    peaks_kib = json.loads(probe.stdout)
    grown_mb = (peaks_kib[-1] - peaks_kib[0]) / 1024
    assert grown_mb < 80, peaks_kib
    assert pq.ParquetFile(tmp_path / "mem" / "parquet" / "samples.parquet").metadata.num_rows == (
        1_600_000
    )
    with (tmp_path / "mem" / "csv" / "samples.csv").open("rb") as f:
        assert sum(1 for _ in f) == 1_600_001
