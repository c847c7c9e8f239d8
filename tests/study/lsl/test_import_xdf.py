"""`study import-xdf`: a LabRecorder recording's streams stored with the trials its
markers name; files without the markers and truncated files refused with one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from db.lsl_streams import read_stream
from db.migrate import open_database
from db.models.lsl import LslChunk, LslStream
from db.models.trial import Trial
from study.cli import main
from study.lsl.markers import MARKER_STREAM, SAMPLE_STREAM_TYPE, encode
from tests.study.conftest import init_study
from tests.study.lsl.xdf_writer import XdfStream, write_xdf

DESIGN = """\
name = "xdf import"
tasks = ["lcca"]
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 1
[lsl]
plot = ["EMG"]
"""
OFFSET_S = 0.25
"""The EMG amplifier's clock offset to the recorder's (pyxdf adds it to its stamps)."""
RATE_HZ = 200.0


@pytest.fixture(scope="module")
def study_db(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, list[Trial]]:
    tmp = tmp_path_factory.mktemp("xdf")
    db = init_study(tmp, DESIGN, ("novice",))
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    engine = open_database(db, create=False)
    with Session(engine) as s:
        trials = s.scalars(select(Trial).order_by(Trial.id)).all()
        for t in trials:
            _ = t.participant.code, t.participant.group
        s.expunge_all()
    engine.dispose()
    return db, trials


def _markers(trials: list[Trial], starts: list[float], length_s: float) -> XdfStream:
    stamps, values = [], []
    session = {"study": "xdf import", "participant": "P001", "group": "novice"}
    stamps.append(starts[0] - 1.0)
    values.append([encode("session_start", **session)])
    for t, start in zip(trials, starts, strict=True):
        keys = {
            "trial_id": t.id,
            "task": t.task,
            "condition": t.condition,
            "block": t.block_index,
            "trial": t.trial_index,
            "practice": t.practice,
            "attempt": t.attempt,
            "clock_rate": 1.0,
        }
        stamps += [start, start + length_s]
        values += [
            [encode("trial_start", **session, **keys)],
            [encode("trial_end", **session, **keys, status="completed")],
        ]
    return XdfStream(MARKER_STREAM, "Markers", "string", 0.0, [("marker", "")], stamps, values)


def _emg(t0: float, n: int) -> XdfStream:
    """A 2-channel EMG stream on the amplifier's clock (the recorder's minus OFFSET_S)."""
    stamps = [t0 + k / RATE_HZ for k in range(n)]
    values = [[float(k), np.sin(k / 10)] for k in range(n)]
    return XdfStream(
        "EMG-amp",
        "EMG",
        "double64",
        RATE_HZ,
        [("index", "count"), ("flexor", "uV")],
        stamps,
        values,
        source_id="amp-1",
        clock_offsets=[(t0, OFFSET_S), (t0 + n / RATE_HZ, OFFSET_S)],
    )


def _recording(tmp: Path, trials: list[Trial], name: str = "rec.xdf") -> Path:
    starts = [100.0, 110.0]  # the recorder's clock
    emg = _emg(95.0 - OFFSET_S, int(25 * RATE_HZ))  # 95 s to 120 s on the recorder's clock
    ours = XdfStream(
        "haptic-study lcca",
        SAMPLE_STREAM_TYPE,
        "double64",
        100.0,
        [("t_s", "s")],
        [100.0, 100.01],
        [[0.0], [0.01]],
    )
    other = XdfStream("PsychoPy", "Markers", "string", 0.0, [("m", "")], [101.0], [["go"]])
    return write_xdf(tmp / name, [_markers(trials, starts, 3.0), emg, ours, other])


def _stored(db: str) -> int:
    engine = open_database(db, create=False)
    with Session(engine) as s:
        n = s.scalar(select(func.count()).select_from(LslStream)) + s.scalar(
            select(func.count()).select_from(LslChunk)
        )
    engine.dispose()
    return n


def _one_line_exit_2(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    assert main(list(args)) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_bad_recordings_are_one_line_and_exit_2_with_nothing_stored(
    study_db: tuple[str, list[Trial]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db, trials = study_db
    good = _recording(tmp_path, trials).read_bytes()
    # no project markers: a recording of the EMG and another program's markers only
    psychopy = XdfStream("PsychoPy", "Markers", "string", 0.0, [("m", "")], [1.0], [["go"]])
    bare = write_xdf(tmp_path / "bare.xdf", [_emg(95.0, 100), psychopy])
    line = _one_line_exit_2(capsys, "import-xdf", str(bare), "--db", db)
    assert "bare.xdf has no haptic-study trial markers" in line
    # cut in the middle of a chunk, and cut where the footers should begin
    cut = tmp_path / "cut.xdf"
    cut.write_bytes(good[: len(good) // 2])
    assert "cut.xdf is truncated: chunk" in _one_line_exit_2(
        capsys, "import-xdf", str(cut), "--db", db
    )
    footer_at = good.index(b"<first_timestamp>")
    nofooter = tmp_path / "nofooter.xdf"
    nofooter.write_bytes(good[: good.rfind(b"\x06\x00", 0, footer_at) - 2])
    line = _one_line_exit_2(capsys, "import-xdf", str(nofooter), "--db", db)
    assert "nofooter.xdf is truncated" in line
    other = tmp_path / "other.xdf"
    # (a name of the same length: the chunks' lengths stay right)
    other.write_bytes(good.replace(b'"study":"xdf import"', b'"study":"xdf pilots"'))
    line = _one_line_exit_2(capsys, "import-xdf", str(other), "--db", db)
    assert "markers are of study 'xdf pilots'; expected this database's study" in line
    notxdf = tmp_path / "notes.xdf"
    notxdf.write_text("hello")
    assert "is not an XDF file" in _one_line_exit_2(capsys, "import-xdf", str(notxdf), "--db", db)
    assert _stored(db) == 0


def test_a_recording_imports_each_streams_samples_to_its_trial(
    study_db: tuple[str, list[Trial]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db, trials = study_db
    path = _recording(tmp_path, trials)
    assert main(["import-xdf", str(path), "--db", db]) == 0
    assert "stored with 2 trial(s)" in capsys.readouterr().out
    engine = open_database(db, create=False)
    with Session(engine) as s:
        streams = s.scalars(select(LslStream).order_by(LslStream.trial_id, LslStream.name)).all()
        s.expunge_all()
    # the EMG and PsychoPy's markers (the session's own sample stream is not imported again)
    assert [(st.trial_id, st.name) for st in streams] == [
        (trials[0].id, "EMG-amp"),
        (trials[0].id, "PsychoPy"),
        (trials[1].id, "EMG-amp"),
        (trials[1].id, "PsychoPy"),
    ]
    for stream, start in ((streams[0], 100.0), (streams[2], 110.0)):
        assert stream.origin == "xdf"
        assert stream.time_correction_s == pytest.approx(OFFSET_S)
        assert [c["name"] for c in stream.channels] == ["index", "flexor"]
        assert [c["unit"] for c in stream.channels] == ["count", "uV"]
        table = read_stream(engine, stream.id)
        index = table["index"].to_numpy()
        # amplifier sample k is at 95 + k / rate on the recorder's clock: the trial's
        # window [start, start + 3 s] holds samples (start - 95) * rate to (start - 92) * rate
        first = round((start - 95.0) * RATE_HZ)
        assert np.array_equal(index, np.arange(first, first + 3 * RATE_HZ + 1))
        np.testing.assert_allclose(table["flexor"].to_numpy(), np.sin(index / 10))
        np.testing.assert_allclose(table["t_s"].to_numpy(), (index - first) / RATE_HZ, atol=1e-9)
    psychopy = read_stream(engine, streams[1].id)
    assert psychopy["m"].to_pylist() == ["go"]
    assert psychopy["t_s"].to_pylist() == [1.0]
    assert read_stream(engine, streams[3].id).num_rows == 0
    engine.dispose()
    # the same recording again: refused, nothing added
    before = _stored(db)
    line = _one_line_exit_2(capsys, "import-xdf", str(path), "--db", db)
    assert "is stored already" in line
    assert _stored(db) == before
    # exported beside the trials' samples: one file per stream, every channel in the codebook
    out = tmp_path / "export"
    assert main(["export", "--out", str(out), "--samples", "--db", db]) == 0
    emg = pd.read_csv(out / "streams" / "EMG-amp.csv")
    assert list(emg.columns) == [
        "participant",
        "task",
        "condition",
        "trial",
        "seq",
        "t_s",
        "lsl_time_s",
        "index",
        "flexor",
    ]
    assert len(emg) == 2 * (3 * RATE_HZ + 1)
    assert set(emg["condition"]) == {t.condition for t in trials}
    assert pd.read_csv(out / "streams" / "PsychoPy.csv")["m"].tolist() == ["go"]
    book = pd.read_csv(out / "codebook.csv").set_index("column")
    assert book.loc["EMG-amp/index", "unit"] == "count"
    assert book.loc["EMG-amp/flexor", "unit"] == "uV"
    assert "PsychoPy/m" in book.index
    assert book.loc["lsl_time_s", "unit"] == "s"
    # drawn in the trial figure, as the design asks ([lsl] plot = ["EMG"])
    figures = tmp_path / "figures"
    assert main(["figures", "--out", str(figures), "--format", "png", "--db", db]) == 0
    assert (figures / "fig9_streams_lcca.png").is_file()
