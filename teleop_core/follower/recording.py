"""The follower recording: what a real bench exports, and the contract the estimator reads.

CSV with a header row and the columns

| column  | unit    | meaning                                        |
|---------|---------|------------------------------------------------|
| `t`     | s       | time, strictly increasing; any sampling rate   |
| `iq`    | A       | measured q-axis current                        |
| `theta` | rad     | wheel angle, unwrapped                         |
| `omega` | rad/s   | wheel speed                                    |
| `f_ref` | N       | reference proximal force (load cell)           |
| `alpha` | rad/s^2 | optional; derived from `omega` when absent     |

Other columns are ignored. A file that breaks the contract (missing column, a cell that
is not a finite number or beyond any signal, time that does not increase, too few rows,
an absurd sampling rate: `teleop_core.recording_checks`) is refused with one line
naming the line and column, before anything is computed from it.

`alpha` is derived causally (a backward difference of `omega` over `t`) so that the
one-sample-at-a-time estimator and the batch estimator see the same acceleration.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError
from teleop_core.files import atomic_path
from teleop_core.recording_checks import check_time, numbers, read_cells

REQUIRED_COLUMNS = ("t", "iq", "theta", "omega", "f_ref")
OPTIONAL_COLUMNS = ("alpha",)
MIN_ROWS = 30
"""Fewest rows a recording may have (a GRU window of 20 plus a few estimates)."""


class RecordingError(TeleopInputError):
    """A recording that breaks the CSV contract."""


def backward_difference(y: Float1D, t: Float1D) -> Float1D:
    """Causal derivative dy/dt: (y[k] - y[k-1]) / (t[k] - t[k-1]); the first value is 0."""
    d = np.zeros_like(y)
    d[1:] = np.diff(y) / np.diff(t)
    return d


@dataclass(frozen=True)
class FollowerRecording:
    """A follower bench recording in SI units; every array has shape (n,)."""

    t: Float1D
    iq: Float1D
    theta: Float1D
    omega: Float1D
    f_ref: Float1D
    alpha: Float1D
    name: str = "recording"

    @classmethod
    def from_arrays(
        cls,
        t: Float1D,
        iq: Float1D,
        theta: Float1D,
        omega: Float1D,
        f_ref: Float1D,
        alpha: Float1D | None = None,
        name: str = "recording",
    ) -> FollowerRecording:
        t = np.asarray(t, dtype=float)
        iq, theta, omega, f_ref = (np.asarray(a, dtype=float) for a in (iq, theta, omega, f_ref))
        alpha_arr = backward_difference(omega, t) if alpha is None else np.asarray(alpha, float)
        return cls(t, iq, theta, omega, f_ref, alpha_arr, name=name)

    @classmethod
    def from_csv(cls, path: str | Path, min_rows: int = MIN_ROWS) -> FollowerRecording:
        """Read and validate a recording; raise `RecordingError` naming the first problem."""
        values = read_checked_csv(path, REQUIRED_COLUMNS, OPTIONAL_COLUMNS, min_rows)
        return cls.from_arrays(
            values["t"],
            values["iq"],
            values["theta"],
            values["omega"],
            values["f_ref"],
            values.get("alpha"),
            name=Path(path).name,
        )

    def __len__(self) -> int:
        return len(self.t)

    @property
    def sample_rate_hz(self) -> float:
        """Median sampling rate, Hz."""
        return float(1.0 / np.median(np.diff(self.t)))

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame(
            {
                "t": self.t,
                "iq": self.iq,
                "theta": self.theta,
                "omega": self.omega,
                "f_ref": self.f_ref,
                "alpha": self.alpha,
            }
        )

    def to_csv(self, path: str | Path) -> None:
        """Write the recording in the CSV contract (with `alpha`), all or nothing."""
        write_csv_atomically(self.to_frame(), Path(path))

    def slice(self, start: int, stop: int) -> FollowerRecording:
        """Samples `start:stop` as a recording of their own."""
        s = slice(start, stop)
        return FollowerRecording(
            self.t[s],
            self.iq[s],
            self.theta[s],
            self.omega[s],
            self.f_ref[s],
            self.alpha[s],
            name=self.name,
        )

    def resampled(self, rate_hz: float) -> FollowerRecording:
        """The recording linearly interpolated onto a uniform grid at `rate_hz`."""
        if not math.isfinite(rate_hz) or rate_hz <= 0:
            raise RecordingError(f"sample rate {rate_hz!r} Hz; expected > 0")
        t = np.arange(self.t[0], self.t[-1] + 1e-12, 1.0 / rate_hz)
        interp = {
            k: np.interp(t, self.t, getattr(self, k)) for k in ("iq", "theta", "omega", "f_ref")
        }
        return FollowerRecording.from_arrays(t, **interp, name=self.name)

    def sha256(self) -> str:
        """Digest of the recording's numbers (identifies the data a model was fitted on)."""
        return hashlib.sha256(self.to_frame().to_numpy().tobytes()).hexdigest()


def read_checked_csv(
    path: str | Path,
    required: tuple[str, ...],
    optional: tuple[str, ...] = (),
    min_rows: int = MIN_ROWS,
) -> dict[str, Float1D]:
    """The named columns of a CSV recording with a strictly increasing `t`, as floats.

    Raises `RecordingError` naming the first problem (file, line, column) before
    anything is computed from the data; the other recording contracts (the master's
    calibration) share these checks.
    """
    path = Path(path)
    frame = read_cells(path, RecordingError)
    missing = [c for c in required if c not in frame.columns]
    if missing:
        extra = f" ({', '.join(optional)} optional)" if optional else ""
        raise RecordingError(
            f"recording {path}: column {missing[0]!r} missing; expected columns "
            f"{', '.join(required)}{extra}, found {', '.join(frame.columns)}"
        )
    wanted = [*required, *[c for c in optional if c in frame.columns]]
    source = f"recording {path}"
    values = {column: numbers(frame, column, source, RecordingError) for column in wanted}
    check_time(values["t"], source, RecordingError, min_rows)
    return values


def write_csv_atomically(frame: pd.DataFrame, path: Path) -> None:
    """Write `frame` to `path` through a temporary file, so a failure leaves no partial file."""
    if not path.parent.is_dir():
        raise TeleopInputError(f"folder {path.parent} for {path.name} does not exist")
    with atomic_path(path) as tmp:
        frame.to_csv(tmp, index=False, float_format="%.9g")
