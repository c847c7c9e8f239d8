"""The follower recording CSV contract: what is read, what is derived, what is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from teleop_core.follower.recording import FollowerRecording, RecordingError


def _write(path: Path, header: str, rows: list[str]) -> Path:
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def _rows(n: int = 40) -> list[str]:
    return [f"{0.01 * i:.2f},{0.1 + 0.001 * i},{0.02 * i},{2.0 + 0.1 * i},{0.5}" for i in range(n)]


def test_alpha_is_derived_as_a_backward_difference(tmp_path: Path) -> None:
    rec = FollowerRecording.from_csv(_write(tmp_path / "r.csv", "t,iq,theta,omega,f_ref", _rows()))
    # omega rises 0.1 rad/s every 0.01 s: 10 rad/s^2 after the first sample, 0 at it.
    assert rec.alpha[0] == 0.0
    np.testing.assert_allclose(rec.alpha[1:], 10.0, rtol=1e-9)
    assert rec.sample_rate_hz == pytest.approx(100.0)


def test_given_alpha_is_kept_and_extra_columns_ignored(tmp_path: Path) -> None:
    rows = [r + f",{-3.0},ignored" for r in _rows()]
    rec = FollowerRecording.from_csv(
        _write(tmp_path / "r.csv", "t,iq,theta,omega,f_ref,alpha,note", rows)
    )
    assert np.all(rec.alpha == -3.0)


def test_round_trip_through_csv(tmp_path: Path, short_recording: FollowerRecording) -> None:
    path = tmp_path / "rec.csv"
    short_recording.to_csv(path)
    back = FollowerRecording.from_csv(path)
    for column in ("t", "iq", "theta", "omega", "f_ref", "alpha"):
        np.testing.assert_allclose(
            getattr(back, column), getattr(short_recording, column), rtol=1e-8, atol=1e-12
        )


@pytest.mark.parametrize(
    ("header", "edit", "message"),
    [
        ("t,iq,theta,f_ref", None, r"column 'omega' missing"),
        (
            "t,iq,theta,omega,f_ref",
            (5, "0.05,nan,0.1,2.5,0.5"),
            r"line 7, column 'iq': 'nan' is not a finite number",
        ),
        ("t,iq,theta,omega,f_ref", (5, "0.05,0.1,,2.5,0.5"), r"line 7, column 'theta': '' is not"),
        (
            "t,iq,theta,omega,f_ref",
            (9, "0.05,0.1,0.1,2.5,0.5"),
            r"line 11, column 't': 0.05 does not come after 0.08",
        ),
        ("t,iq,theta,omega,f_ref", (3, "0.03,0.1,0.1,fast,0.5"), r"line 5, column 'omega': 'fast'"),
    ],
)
def test_bad_recordings_are_refused_naming_line_and_column(
    tmp_path: Path, header: str, edit: tuple[int, str] | None, message: str
) -> None:
    rows = _rows()
    if edit is not None:
        rows[edit[0]] = edit[1]
    if header.count(",") == 3:
        rows = [",".join(r.split(",")[:3] + r.split(",")[4:]) for r in rows]
    with pytest.raises(RecordingError, match=message):
        FollowerRecording.from_csv(_write(tmp_path / "bad.csv", header, rows))


def test_too_little_data_is_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match=r"has 12 data rows; expected at least 30"):
        FollowerRecording.from_csv(
            _write(tmp_path / "short.csv", "t,iq,theta,omega,f_ref", _rows(12))
        )


def test_missing_and_empty_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="does not exist; expected a CSV file"):
        FollowerRecording.from_csv(tmp_path / "absent.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(RecordingError, match="is empty"):
        FollowerRecording.from_csv(tmp_path / "empty.csv")


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        # each was accepted (and failed later) or gave a traceback
        (
            lambda h, rows: (h, ["0.00,1e300,0,2,0.5", *rows[1:]]),
            r"line 2, column 'iq': '1e300' is beyond ±1e\+12; expected a value in SI units",
        ),
        (
            lambda h, rows: (h, [*rows[:5], rows[4], *rows[6:]]),
            r"line 7, column 't': 0.04 repeats 0.04 on the line before; expected strictly",
        ),
        (
            lambda h, rows: (
                h,
                [f"{1e-9 * i!r}," + r.split(",", 1)[1] for i, r in enumerate(rows)],
            ),
            r"column 't', lines 2-41: median step 1e-09 s \(1e\+09 Hz\); expected a sampling rate "
            r"from 10 Hz to 1e\+06 Hz",
        ),
        (
            lambda h, rows: (h, [f"{10 * i}," + r.split(",", 1)[1] for i, r in enumerate(rows)]),
            r"median step 10 s \(0.1 Hz\)",
        ),
        (
            lambda h, rows: (h + ",iq", [r + ",1" for r in rows]),
            r"line 1: column 'iq' appears twice; expected distinct column names",
        ),
        (
            lambda h, rows: (h, [*rows[:3], rows[3].rsplit(",", 1)[0], *rows[4:]]),
            r"line 5, column 'f_ref': '' is not a finite number; expected a plain decimal",
        ),
    ],
)
def test_nonsense_is_refused_with_one_line_naming_line_column_and_expectation(
    tmp_path: Path,
    edit,
    message: str,  # type: ignore[no-untyped-def]
) -> None:
    header, rows = edit("t,iq,theta,omega,f_ref", _rows())
    with pytest.raises(RecordingError, match=message) as caught:
        FollowerRecording.from_csv(_write(tmp_path / "bad.csv", header, rows))
    assert "\n" not in str(caught.value)


def test_a_folder_or_non_utf8_file_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="is not a readable CSV file"):
        FollowerRecording.from_csv(tmp_path)
    (tmp_path / "latin1.csv").write_bytes("t,iq,theta,omega,f_ref\n0,é,0,0,0\n".encode("latin-1"))
    with pytest.raises(RecordingError, match=r"is not UTF-8 text \(byte 0xe9"):
        FollowerRecording.from_csv(tmp_path / "latin1.csv")
