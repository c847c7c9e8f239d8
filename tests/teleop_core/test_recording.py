"""The follower recording CSV contract: what is read, what is derived, what is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from teleop_core.estimation.recording import FollowerRecording, RecordingError


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
    with pytest.raises(RecordingError, match="does not exist"):
        FollowerRecording.from_csv(tmp_path / "absent.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(RecordingError, match="is empty"):
        FollowerRecording.from_csv(tmp_path / "empty.csv")
