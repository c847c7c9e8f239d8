"""Property-based tests over the recording parsers.

The CSV recordings that `study calibrate`, `study estimator train/run` and `study
identify` read (follower, master, NOTES, rigid-axis) are generated valid and then
broken in up to three ways: a junk cell, a missing or repeated column, time out of
order or repeated, too few rows, a time column in the wrong unit (an absurd sampling
rate), a short row, non-UTF-8 bytes, an empty file. Every input is either accepted, and
then holds only what the contract allows (finite values within range, strictly
increasing time at a plausible rate, enough rows), or refused with one line naming the
recording; the command then exits 2 with that one line and writes nothing.

4 contracts x (200 parser cases + 50 command cases): 1,000 generated inputs a run. An
accepted input is not run through the fit here (training a GRU per example would take
hours); the commands' own tests run accepted recordings.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from study.cli import main
from teleop_core.calibration.models import MASTER_COLUMNS
from teleop_core.calibration.rigid_axis import RIGID_COLUMNS, read_numeric_csv
from teleop_core.errors import TeleopInputError
from teleop_core.follower.recording import OPTIONAL_COLUMNS, REQUIRED_COLUMNS, read_checked_csv
from teleop_core.notes.recording import NotesRecording
from teleop_core.recording_checks import MAX_ABS_VALUE, MAX_RATE_HZ, MIN_RATE_HZ


@dataclass(frozen=True)
class Contract:
    columns: tuple[str, ...]
    min_rows: int
    parse: Callable[[Path], dict[str, np.ndarray]]
    argv: Callable[[Path, Path], list[str]]


def _notes(path: Path) -> dict[str, np.ndarray]:
    rec = NotesRecording.from_csv(path)
    return {"t": rec.t, "f_des": rec.f_des, "f_ee": rec.y}


def _rigid(path: Path) -> dict[str, np.ndarray]:
    frame = read_numeric_csv(path, RIGID_COLUMNS)
    return {c: frame[c].to_numpy(float) for c in frame.columns}


def _calibrate(model: str) -> Callable[[Path, Path], list[str]]:
    def argv(rec: Path, out: Path) -> list[str]:
        return [
            "calibrate",
            "--model",
            model,
            str(rec),
            "--json",
            str(out / "r.json"),
            "--predictions",
            str(out / "p.csv"),
            "--out",
            str(out / "figs"),
        ]

    return argv


CONTRACTS = {
    "follower": Contract(
        REQUIRED_COLUMNS,
        30,
        lambda p: read_checked_csv(p, REQUIRED_COLUMNS, OPTIONAL_COLUMNS),
        lambda rec, out: ["estimator", "train", str(rec), "--out", str(out / "model")],
    ),
    "master": Contract(
        MASTER_COLUMNS, 30, lambda p: read_checked_csv(p, MASTER_COLUMNS), _calibrate("master")
    ),
    "notes": Contract(
        ("t", "f_des", "f_ee"),
        200,
        _notes,
        lambda rec, out: [
            "identify",
            "notes",
            "--dof",
            "translation",
            str(rec),
            "--json",
            str(out / "r.json"),
        ],
    ),
    "rigid": Contract(RIGID_COLUMNS, 200, _rigid, _calibrate("rigid-axis")),
}
N_ROWS = 205
JUNK = [
    "",
    " ",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e400",
    "-1e300",
    "1e13",
    "3_0",
    "0x10",
    "²",
    "1,5",
    "true",
    "=1+1",
    "\u00a0",
    "é",
    "99999999999999999999999",
    '"',
    "1e-400",
]
T_SCALES = [1e-9, 1e-6, 1e-3, 1.0, 1e3, 1e6, 1e300]


def _valid(columns: tuple[str, ...]) -> list[list[str]]:
    t = np.arange(N_ROWS) * 1e-3
    rows = [list(columns)]
    for k, tk in enumerate(t):
        signals = (repr(float(np.sin(0.1 * k + j))) for j in range(1, len(columns)))
        rows.append([repr(float(tk)), *signals])
    return rows


@st.composite
def _broken(draw: st.DrawFn, columns: tuple[str, ...]) -> bytes:
    rows = _valid(columns)
    for _ in range(draw(st.integers(0, 3))):
        kind = draw(
            st.sampled_from(
                [
                    "cell",
                    "cell",
                    "drop",
                    "repeat",
                    "time",
                    "short",
                    "scale",
                    "ragged",
                    "bytes",
                    "empty",
                ]
            )
        )
        n = len(rows)
        if kind == "cell" and n > 1:
            r, c = draw(st.integers(1, n - 1)), draw(st.integers(0, len(rows[0]) - 1))
            if c < len(rows[r]):
                rows[r][c] = draw(st.one_of(st.sampled_from(JUNK), st.text(max_size=4)))
        elif kind == "drop" and len(rows[0]) > 1:
            c = draw(st.integers(0, len(rows[0]) - 1))
            rows = [row[:c] + row[c + 1 :] for row in rows]
        elif kind == "repeat":
            rows = [[*row, row[-1]] for row in rows]  # a column name twice
        elif kind == "time" and n > 3:
            r = draw(st.integers(2, n - 1))
            rows[r][0] = rows[r - draw(st.integers(0, 1)) - 1][0]  # repeated or backwards
        elif kind == "short":
            rows = rows[: draw(st.integers(1, n))]
        elif kind == "scale" and n > 1:
            scale = draw(st.sampled_from(T_SCALES))
            for row in rows[1:]:
                with contextlib.suppress(ValueError, IndexError):
                    row[0] = repr(float(row[0]) * scale)
        elif kind == "ragged" and n > 1:
            r = draw(st.integers(1, n - 1))
            rows[r] = rows[r][:-1] if draw(st.booleans()) else [*rows[r], "7"]
        elif kind == "bytes":
            return ("\n".join(",".join(row) for row in rows)).encode() + b"\n\xff\xfe,\x80\n"
        elif kind == "empty":
            return b"" if draw(st.booleans()) else (",".join(rows[0]) + "\n").encode()
    return "".join(",".join(row) + "\n" for row in rows).encode("utf-8")


def _accepted_or_one_line(contract: Contract, path: Path) -> str | None:
    """None if the parser accepts `path` (checking what it holds), else its message."""
    try:
        values = contract.parse(path)
    except TeleopInputError as exc:
        message = str(exc)
        assert "\n" not in message, message
        assert message, message
        assert str(path) in message, message
        return message
    t = values["t"]
    assert len(t) >= contract.min_rows
    assert set(contract.columns) <= set(values)
    for v in values.values():
        assert np.all(np.isfinite(v))
        assert np.all(np.abs(v) <= MAX_ABS_VALUE)
    assert np.all(np.diff(t) > 0)
    assert MIN_RATE_HZ <= 1.0 / float(np.median(np.diff(t))) <= MAX_RATE_HZ
    return None


@pytest.mark.parametrize("name", list(CONTRACTS))
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_recording_is_accepted_within_the_contract_or_refused_with_one_line(
    name: str, data: st.DataObject
) -> None:
    contract = CONTRACTS[name]
    content = data.draw(_broken(contract.columns))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "rec.csv"
        path.write_bytes(content)
        _accepted_or_one_line(contract, path)


def _run(argv: list[str]) -> tuple[int, list[str]]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(argv)
    return rc, err.getvalue().strip().splitlines()


@pytest.mark.parametrize("name", list(CONTRACTS))
@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
@example(data=None)  # a fixed case first: the time column in milliseconds
def test_a_refused_recording_stops_its_command_with_one_line_and_no_output(
    name: str, data: st.DataObject | None
) -> None:
    contract = CONTRACTS[name]
    if data is None:
        rows = _valid(contract.columns)
        content = "".join(
            ",".join([repr(float(r[0]) * 1e3) if i else r[0], *r[1:]]) + "\n"
            for i, r in enumerate(rows)
        ).encode()
    else:
        content = data.draw(_broken(contract.columns))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "rec.csv"
        path.write_bytes(content)
        message = _accepted_or_one_line(contract, path)
        if message is None:
            return  # accepted: running the fit is the commands' own tests' business
        out = Path(folder) / "out"
        out.mkdir()
        rc, err = _run(contract.argv(path, out))
        assert rc == 2, err
        assert len(err) == 1, (err, message)
        assert err[0].endswith(message), (err, message)
        assert list(out.iterdir()) == []


@pytest.mark.parametrize("name", list(CONTRACTS))
def test_an_all_zero_recording_is_one_line_and_no_output(name: str, tmp_path: Path) -> None:
    """All-zero recordings gave tracebacks (a division by zero in the
    fit) from calibrate, estimator train and identify notes."""
    contract = CONTRACTS[name]
    rows = _valid(contract.columns)
    path = tmp_path / "zero.csv"
    path.write_text(
        "".join(
            ",".join([r[0], *("0" for _ in r[1:])]) + "\n" if i else ",".join(r) + "\n"
            for i, r in enumerate(rows)
        )
    )
    out = tmp_path / "out"
    out.mkdir()
    rc, err = _run(contract.argv(path, out))
    assert rc == 2, err
    assert len(err) == 1, err
    assert "on every" in err[0]
    assert "expected" in err[0]
    assert list(out.iterdir()) == []
