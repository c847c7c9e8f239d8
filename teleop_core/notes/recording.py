"""The NOTES bench recording: the CSV contract the characterisation reads.

| column  | unit         | meaning                                                  |
|---------|--------------|----------------------------------------------------------|
| `t`     | s            | time, strictly increasing, uniformly sampled             |
| `f_des` | N or N m     | commanded force (translation) or torque (rotation)       |
| `x`     | m or rad     | end-effector position, open-ended runs (Fig. 5, left)    |
| `f_ee`  | N or N m     | load-cell force or torque, clamped runs (Fig. 5, right)  |

A recording has `x` or `f_ee`, not both; which one says the boundary condition. Other
columns are ignored. Anything else is refused with one line naming the file, the row
(the CSV's line number, header = line 1) and the column, before any computation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError
from teleop_core.recording_checks import check_time, read_cells
from teleop_core.recording_checks import numbers as check_numbers

MIN_ROWS = 200
"""Fewest rows: 0.2 s at 1 kHz, below which no 1 Hz content is measurable."""
UNIFORM_TOLERANCE = 0.01
"""Largest relative deviation of a time step from the median step."""


class NotesRecordingError(TeleopInputError):
    """A NOTES recording that breaks the CSV contract."""


@dataclass(frozen=True)
class NotesRecording:
    """One bench run of one axis; arrays of shape (n,)."""

    t: Float1D
    """Time, s."""
    f_des: Float1D
    """Commanded force or torque, N or N m."""
    y: Float1D
    """Measured position x (open) or force f_ee (clamped)."""
    boundary: str
    """"open" (y is x) or "clamped" (y is f_ee)."""

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t)))

    @property
    def experiment(self) -> str:
        """ "ramp" when the command reverses at most a few times, else "chirp"."""
        df = np.diff(self.f_des)
        s = np.sign(df[np.abs(df) > 1e-12 * max(np.max(np.abs(self.f_des)), 1e-300)])
        return "ramp" if np.count_nonzero(s[1:] != s[:-1]) <= 4 else "chirp"

    def to_frame(self) -> pd.DataFrame:
        """The recording in its CSV columns."""
        column = "x" if self.boundary == "open" else "f_ee"
        return pd.DataFrame({"t": self.t, "f_des": self.f_des, column: self.y})

    @classmethod
    def from_frame(cls, frame: pd.DataFrame, source: str = "recording") -> NotesRecording:
        """Validate a frame of strings or numbers; `source` names it in errors."""
        frame = frame.rename(columns=lambda c: str(c).strip())
        has = [c for c in ("x", "f_ee") if c in frame.columns]
        for column in ("t", "f_des"):
            if column not in frame.columns:
                raise NotesRecordingError(
                    f"{source}: column {column!r} missing; expected t, f_des and x (open end) "
                    f"or f_ee (clamped), found {', '.join(map(str, frame.columns))}"
                )
        if len(has) != 1:
            what = "both x and f_ee" if has else "neither x nor f_ee"
            raise NotesRecordingError(
                f"{source}: {what}; expected exactly one (x open-ended, f_ee clamped)"
            )
        columns = ["t", "f_des", has[0]]
        numbers = {c: check_numbers(frame, c, source, NotesRecordingError, "row") for c in columns}
        check_time(numbers["t"], source, NotesRecordingError, MIN_ROWS, "row")
        step = np.diff(numbers["t"])
        median = float(np.median(step))
        bad = np.flatnonzero(np.abs(step - median) > UNIFORM_TOLERANCE * median)
        if bad.size:
            row = int(bad[0]) + 1
            raise NotesRecordingError(
                f"{source}, row {row + 2}, column 't': step {step[bad[0]]!r} s; expected "
                f"uniform sampling at {median!r} s"
            )
        boundary = "open" if has[0] == "x" else "clamped"
        return cls(numbers["t"], numbers["f_des"], numbers[has[0]], boundary)

    @classmethod
    def from_csv(cls, path: str | Path) -> NotesRecording:
        """Read and validate a CSV file; raise `NotesRecordingError` naming the problem."""
        path = Path(path)
        frame = read_cells(path, NotesRecordingError)
        return cls.from_frame(frame, f"recording {path}")
