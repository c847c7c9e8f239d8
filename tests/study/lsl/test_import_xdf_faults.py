"""`study import-xdf` on recordings whose markers or streams are wrong: every marker
field is checked before anything is stored, a file pyxdf can read only in part is
refused, and pyxdf's own log output never reaches the terminal. Each case: one line
naming the value and what was expected, exit status 2, nothing stored."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from db.models.trial import Trial
from study.cli import main
from study.lsl.markers import KEY, MARKER_STREAM, VERSION
from tests.study.lsl.test_import_xdf import _emg, _stored, study_db
from tests.study.lsl.xdf_writer import XdfStream, write_xdf

__all__ = ["study_db"]  # the fixture, shared with the import's own tests


def _keys(trial: Trial) -> dict[str, Any]:
    return {
        "study": "xdf import",
        "participant": "P001",
        "group": "novice",
        "trial_id": trial.id,
        "task": trial.task,
        "condition": trial.condition,
        "block": trial.block_index,
        "trial": trial.trial_index,
        "practice": trial.practice,
        "attempt": trial.attempt,
        "clock_rate": 1.0,
    }


def _marker(event: str, fields: dict[str, Any]) -> list[object]:
    return [json.dumps({KEY: VERSION, "event": event, **fields})]


def _recording(
    tmp: Path,
    trial: Trial,
    start: dict[str, Any] | None = None,
    events: list[tuple[float, str]] | None = None,
    emg: XdfStream | None = None,
) -> Path:
    """One trial's markers (its trial_start's fields replaced by `start`, None values
    dropped; `events`: the (stamp, event) sequence, default start then end) and EMG."""
    fields = {**_keys(trial), **(start or {})}
    fields = {k: v for k, v in fields.items() if v is not _DROP}
    end = _keys(trial)
    sequence = events or [(100.0, "trial_start"), (103.0, "trial_end")]
    stamps = [t for t, _ in sequence]
    values = [_marker(e, fields if e == "trial_start" else end) for _, e in sequence]
    markers = XdfStream(MARKER_STREAM, "Markers", "string", 0.0, [("m", "")], stamps, values)
    return write_xdf(tmp / "rec.xdf", [markers, emg or _emg(99.0, 1000)])


_DROP = object()


def _refused(capsys: pytest.CaptureFixture[str], path: Path, db: str) -> str:
    code = main(["import-xdf", str(path), "--db", db])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2, captured
    assert len(lines) == 1, lines
    assert "Traceback" not in captured.err
    assert captured.out == ""
    assert _stored(db) == 0
    return lines[0]


FIELD_CASES = [
    *[
        ({name: _DROP}, f"has no field {name!r}")
        for name in ("participant", "block", "trial", "practice", "attempt", "study", "clock_rate")
    ],
    ({"block": "zero"}, 'block = "zero"; expected a whole number'),
    ({"block": None}, "block = null; expected a whole number"),
    ({"block": [1]}, "block = [1]; expected a whole number"),
    ({"block": 1e20}, "block = 1e+20; expected a whole number"),
    ({"trial": 1.5}, "trial = 1.5; expected a whole number"),
    ({"attempt": -1}, "attempt = -1; expected a whole number from 0"),
    ({"practice": "no"}, 'practice = "no"; expected true or false'),
    ({"practice": 0}, "practice = 0; expected true or false"),
    ({"clock_rate": "fast"}, 'clock_rate = "fast"; expected a number above 0'),
    ({"clock_rate": -1}, "clock_rate = -1; expected a number above 0"),
    ({"clock_rate": 0}, "clock_rate = 0; expected a number above 0"),
    ({"clock_rate": "nan"}, 'clock_rate = "nan"; expected a number above 0'),
    ({"participant": ""}, 'participant = ""; expected a participant code'),
]


@pytest.mark.parametrize("start, expect", FIELD_CASES, ids=[e for _, e in FIELD_CASES])
def test_every_marker_field_is_checked_before_anything_is_stored(
    study_db: tuple[str, list[Trial]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    start: dict[str, Any],
    expect: str,
) -> None:
    db, trials = study_db
    line = _refused(capsys, _recording(tmp_path, trials[0], start), db)
    assert "the trial_start marker at 100.000 s" in line, line
    assert expect in line, line


@pytest.mark.parametrize(
    "events, expect",
    [
        (
            [(100.0, "trial_start"), (101.0, "trial_start"), (103.0, "trial_end")],
            "a second trial_start of trial_id",
        ),
        (
            [(100.0, "trial_start"), (103.0, "trial_end"), (104.0, "trial_end")],
            "a second trial_end of trial_id",
        ),
        ([(103.0, "trial_end")], "a trial_end of trial_id"),
    ],
    ids=["start twice", "end twice", "end without start"],
)
def test_repeated_or_unmatched_markers_make_the_file_inconsistent(
    study_db: tuple[str, list[Trial]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    events: list[tuple[float, str]],
    expect: str,
) -> None:
    db, trials = study_db
    line = _refused(capsys, _recording(tmp_path, trials[0], events=events), db)
    assert "rec.xdf is inconsistent: " in line, line
    assert expect in line, line


class _WrongHeader(XdfStream):
    """A stream whose header declares other than its data hold."""

    declared: tuple[str, str] = ("", "")

    def header(self) -> str:
        return super().header().replace(*self.declared)


def test_a_stream_whose_data_do_not_fit_its_header_is_refused_not_half_stored(
    study_db: tuple[str, list[Trial]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db, trials = study_db
    good = _emg(99.0, 1001)
    emg = _WrongHeader(**{k: getattr(good, k) for k in good.__dataclass_fields__})
    emg.declared = ("<channel_count>2</channel_count>", "<channel_count>3</channel_count>")
    line = _refused(capsys, _recording(tmp_path, trials[0], emg=emg), db)
    assert "expected a consistent recording" in line, line
    assert "could be read only in part" in line or "footer counts 1001" in line, line


def test_a_marker_stream_declared_float32_is_one_line(
    study_db: tuple[str, list[Trial]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db, trials = study_db
    path = _recording(tmp_path, trials[0])
    data = path.read_bytes()
    # the same number of bytes: "string" and "int32 " differ in the header text only
    path.write_bytes(data.replace(b">string</channel_format>", b">int32</channel_format> ", 1))
    line = _refused(capsys, path, db)
    assert "rec.xdf" in line, line
