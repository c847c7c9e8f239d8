"""`rigid-axis`: the inverse dynamics of one rigid axis, for any drive's recording.

The base model of the identification literature's inverse dynamic identification
model (IDIM-LS; Gautier, Janot et al.), linear in its parameters:

    u = M q'' + Fv q' + Fc sgn(q') + offset

on the recording contract `t, q, u` (SI: `t` in s, `q` in m or rad, `u` the actuator
force in N or torque in N m). Every other numeric column is an extra channel that the
base model ignores and the loop's effects and residual analysis may use (a load cell,
a temperature, the current).

Velocity and acceleration come from the position as IDIM does for inverse models: a
zero-phase low-pass filter (`scipy.signal.filtfilt`, a 4th-order Butterworth run
forwards and backwards, so no lag enters the regressors) followed by central
differences (`numpy.gradient`). The cutoff is one of the base model's own
assumptions, so it is fitted: the one of 16 cutoffs from 1/200 to 1/5 of the sampling
rate (log-spaced) whose base-model fit has the lowest RMSE on the training block
(the held-out block never sees the choice). Too low a cutoff lags the acceleration
behind the force it causes; too high a one lets quantisation noise through every
differentiation. Where cutoffs fit within 1 % of the best, the highest of them is
taken. On the EMPS benchmark it picks 75-100 Hz at 1 kHz, where the fitted
M, Fv, Fc and offset come within 1 % of the benchmark's reference values.

sgn(q') is the sharp sign of the filtered velocity, not eq. 1's tanh(w / 0.3): a real
drive's Coulomb step is as sharp as the data show it.

The axis is linear (`q` in m, `u` in N) or rotary (`q` in rad, `u` in N m): the
parameters' names and the reports' units follow it. A recording may say which in its
column names, by the unit suffix of `q` and `u` (`q_m`, `u_n`; `q_rad`, `u_n_m`, as the
project names quantities); without one the axis is the one the model is given
(`axis`, linear by default).

`mat_to_frame` brings a MATLAB v5 `.mat` recording (the EMPS benchmark's, say) into the
contract: variables named for `q` and `u` (products of variables, `gtau*vir`, are
allowed), every other vector of the same length as an extra channel.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal

from teleop_core._typing import Float1D, Float2D
from teleop_core.calibration.effects import DirectionAsymmetry, Signals, Stribeck
from teleop_core.calibration.models import BaseModel, CalibrationData
from teleop_core.errors import TeleopInputError
from teleop_core.follower.recording import RecordingError
from teleop_core.recording_checks import check_time, numbers, read_cells

RIGID_COLUMNS = ("t", "q", "u")
"""The rigid-axis recording contract: time [s], position [m or rad], force [N or N m]."""
AXES = ("linear", "rotary")
"""Kinds of axis: linear (q in m, u in N) or rotary (q in rad, u in N m)."""
UNIT_SUFFIXES: dict[str, dict[str, str]] = {
    "q": {"_rad": "rotary", "_m": "linear"},
    "u": {"_n_m": "rotary", "_n": "linear"},
}
"""Unit suffixes of the contract's `q` and `u` columns, and the axis each says (the
longer suffix is tried first: `u_n_m` is no `u_n`)."""
AXIS_UNITS = {
    "linear": {"output": "N", "position": "m"},
    "rotary": {"output": "N m", "position": "rad"},
}
"""Units of the output and of the position of each kind of axis."""
MIN_ROWS = 200
"""Fewest samples of a rigid-axis recording."""
CUTOFF_FRACTION = 1.0 / 40.0
"""Low-pass cutoff as a fraction of the sampling rate where none is given or fitted."""


EDGE_FIT = 20
"""Samples at each end of the position to which `_extend` fits its quadratic."""
EDGE_PERIODS = 4.0
"""Length of the extension at each end, in periods of the cutoff (the filter's transient
dies out well within it)."""


def _extend(q: Float1D, pad: int) -> Float1D:
    """`q` with `pad` samples added at each end: the quadratic fitted to its `EDGE_FIT`
    end samples, carried on.

    `filtfilt`'s own padding (an odd reflection) keeps the slope at an end but forces
    the curvature to zero there, so a recording that ends mid-motion gets a false
    acceleration in its last samples (on EMPS, tens of N of inertial force in the last
    10 ms). scipy offers odd, even, constant and Gustafsson's start values, none of
    which carries the acceleration on; a quadratic's extrapolation does, in three lines.
    """
    fit = min(EDGE_FIT, len(q))
    k = np.arange(fit, dtype=float)
    left = np.polyval(np.polyfit(k, q[:fit], 2), np.arange(-pad, 0, dtype=float))
    right = np.polyval(np.polyfit(k, q[-fit:], 2), fit + np.arange(pad, dtype=float))
    return np.concatenate([left, q, right])


def derivatives(
    t: Float1D, q: Float1D, cutoff_hz: float | None = None
) -> tuple[Float1D, Float1D, Float1D, float]:
    """Zero-phase filtered position, velocity and acceleration, and the cutoff used.

    A 4th-order Butterworth low-pass run forwards and backwards (`filtfilt`, so the
    filtered signal has no phase lag) over the position extended at both ends by its
    local quadratic (`_extend`: no false acceleration at the ends), then central
    differences over `t` (second-order one-sided ones at the two ends).
    """
    fs = 1.0 / float(np.median(np.diff(t)))
    cutoff = fs * CUTOFF_FRACTION if cutoff_hz is None else float(cutoff_hz)
    if not 0 < cutoff < fs / 2:
        raise TeleopInputError(
            f"cutoff {cutoff!r} Hz; expected between 0 and half the sampling rate {fs / 2:.4g} Hz"
        )
    b, a = signal.butter(4, cutoff / (fs / 2))
    pad = int(np.ceil(EDGE_PERIODS * fs / cutoff))
    qf = signal.filtfilt(b, a, _extend(q, pad), padtype=None)[pad:-pad]
    qd = np.gradient(qf, t, edge_order=2)
    qdd = np.gradient(qd, t, edge_order=2)
    return qf, qd, qdd, cutoff


class AxisStribeck(Stribeck):
    """Stribeck friction on the axis's own speed scale (m/s or rad/s), sharp sign."""

    def grid(self, s: Signals) -> Float1D:
        top = float(np.percentile(np.abs(s["speed"]), 99))
        return np.geomspace(0.003, 0.6, 28) * top

    def columns(self, s: Signals, value: float) -> Float2D:
        w = s["speed"]
        return (-np.exp(-((w / value) ** 2)) * s["direction_sign"])[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"static_minus_coulomb_{unit}": coef[0] * out, "stribeck_speed": value}


class AxisDirection(DirectionAsymmetry):
    """Direction-dependent viscous friction: with the benchmark's direction-dependent
    Coulomb friction, its direction-dependent inverse model.

    The extra Coulomb friction in reverse has no column of its own: under the sharp
    sign the base's Fc sgn(q') + offset is already any constant force forwards
    (Fc + offset) and any other in reverse (offset - Fc), so a reverse step
    (-min(sgn q', 0) = (1 - sgn q') / 2 wherever q' != 0) is a sum of the base's
    columns: with it the design would be singular, and the forces split among Fc,
    offset and the step arbitrarily."""

    def columns(self, s: Signals, value: float) -> Float2D:
        return -np.minimum(s["direction"], 0.0)[:, None]

    def physical(self, coef: Float1D, value: float, out: float, unit: str) -> dict[str, float]:
        return {f"extra_viscous_reverse_{unit}_s_per_unit": coef[0] * out}


@dataclass(frozen=True)
class RigidAxisBase(BaseModel):
    """u = M q'' + Fv q' + Fc sgn(q') + offset, on `t, q, u` (+ extra channels)."""

    cutoff_hz: float | None = None
    """Low-pass cutoff for the derivatives [default: fitted on the training block]."""
    train_fraction: float = 0.75
    """The loop's training share (the start of the recording), where the cutoff is fitted."""
    axis: str = "linear"
    """"linear" (q in m, u in N) or "rotary" (q in rad, u in N m)."""

    name = "rigid-axis"
    families = ("direction_asymmetry", "stribeck", "viscous_nonlinear", "position_periodic")
    plot_against = ("t", "speed", "angle")
    overrides = {  # noqa: RUF012 - read only
        "stribeck": AxisStribeck(),
        "direction_asymmetry": AxisDirection(),
    }

    def __post_init__(self) -> None:
        if self.axis not in AXES:
            raise TeleopInputError(f"axis {self.axis!r}; expected one of {', '.join(AXES)}")

    @property
    def unit(self) -> str:  # type: ignore[override]
        return "n" if self.axis == "linear" else "n_m"

    @property
    def output_unit(self) -> str:  # type: ignore[override]
        return AXIS_UNITS[self.axis]["output"]

    def units(self) -> dict[str, str]:
        return {"axis": self.axis, **AXIS_UNITS[self.axis]}

    def reader_for(self, preparation: dict[str, float] | None) -> RigidAxisBase:
        """With the training recording's derivative cutoff: the validation recording's
        velocity and acceleration filtered alike (its own fitted cutoff would fit the
        base model to it)."""
        cutoff = (preparation or {}).get("derivative_cutoff_hz")
        return self if cutoff is None else replace(self, cutoff_hz=float(cutoff))

    def columns(self, s: Signals) -> Float2D:
        # u = M q'' + Fv q' + Fc sgn(q') + offset
        w = s["speed"]
        return np.column_stack([s["accel"], w, s["direction_sign"], np.ones_like(w)])

    def physical(self, coef: Float1D) -> dict[str, float]:
        names = (
            ("mass_kg", "viscous_friction_n_s_per_m", "coulomb_friction_n", "offset_n")
            if self.axis == "linear"
            else (
                "inertia_kg_m2",
                "viscous_friction_n_m_s_per_rad",
                "coulomb_friction_n_m",
                "offset_n_m",
            )
        )
        return {name: float(c) for name, c in zip(names, coef[:4], strict=True)}

    def data_from_frame(self, frame: pd.DataFrame, name: str = "recording") -> CalibrationData:
        t, q, u = (frame[c].to_numpy(float) for c in RIGID_COLUMNS)
        cutoff = self.cutoff_hz
        if cutoff is None:
            cutoff = fit_cutoff(t, q, u, self.columns_of, int(self.train_fraction * len(t)))
        qf, qd, qdd, cutoff = derivatives(t, q, cutoff)
        signals: Signals = {
            "t": t,
            "angle": qf,
            "speed": qd,
            "accel": qdd,
            "direction": qd,
            "direction_sign": np.sign(qd),
        }
        for column in frame.columns:
            if column not in RIGID_COLUMNS and column not in signals:
                signals[column] = frame[column].to_numpy(float)
        return CalibrationData(signals, u, name, preparation={"derivative_cutoff_hz": cutoff})

    def columns_of(self, qd: Float1D, qdd: Float1D) -> Float2D:
        return self.columns({"speed": qd, "accel": qdd, "direction_sign": np.sign(qd)})

    mat_columns: tuple[str, str, str] | None = None
    """Variables (or products) of a `.mat` recording for t, q and u, e.g. EMPS's
    `("t", "qm", "gtau*vir")`; a `.mat` recording cannot be read without them."""

    def read(self, path: str | Path) -> CalibrationData:
        path = Path(path)
        said: dict[str, str] = {}
        if path.suffix.lower() == ".mat":
            if self.mat_columns is None:
                raise RecordingError(
                    f"recording {path} is a MATLAB file; expected the names of its "
                    "variables for t, q and u (mat_columns, e.g. t, qm, gtau*vir)"
                )
            t, q, u = self.mat_columns
            said.update(q=q, u=u)
            frame = mat_to_frame(path, q=q, u=u, t=t)
        else:
            frame = read_numeric_csv(path, RIGID_COLUMNS, said)
        axis = axis_of(said, path)
        if axis is not None and axis != self.axis:
            named = " and ".join(f"{v!r}" for v in said.values() if _suffix_axis(v, said))
            raise RecordingError(
                f"recording {path}: {named} name a {axis} axis; expected the "
                f"{self.axis} axis the calibration is of"
            )
        return self.data_from_frame(frame, path.name)


def fit_cutoff(t: Float1D, q: Float1D, u: Float1D, columns, n_train: int) -> float:
    """The derivative cutoff whose base fit has the lowest training RMSE (see above)."""
    fs = 1.0 / float(np.median(np.diff(t)))
    cutoffs = np.geomspace(fs / 200.0, fs / 5.0, 16)
    sse = []
    for cutoff in cutoffs:
        _, qd, qdd, _ = derivatives(t, q, cutoff)
        X = columns(qd, qdd)[:n_train]
        coef, *_ = np.linalg.lstsq(X, u[:n_train], rcond=None)
        sse.append(float(np.sum((u[:n_train] - X @ coef) ** 2)))
    # the highest cutoff within 1 % of the best fit: where the fit cannot tell them
    # apart (a clean position signal), the least filtering distorts the least
    near = np.flatnonzero(np.asarray(sse) <= 1.01 * min(sse))
    return float(cutoffs[near[-1]])


def contract_columns(header: Sequence[str], path: str | Path) -> dict[str, str]:
    """The column that holds `q` and the one that holds `u` in a CSV `header`: the
    contract's name or the name with a unit suffix (`UNIT_SUFFIXES`); the names
    themselves where neither is there (the contract check names what is missing).

    Raises
    ------
    RecordingError
        Two columns hold the same quantity (`q` and `q_m`, say).
    """
    out = {}
    for name, suffixes in UNIT_SUFFIXES.items():
        found = [c for c in header if c == name or c in {name + s for s in suffixes}]
        if len(found) > 1:
            raise RecordingError(
                f"recording {path}: columns {' and '.join(map(repr, found))} both hold "
                f"{name!r}; expected one of them"
            )
        out[name] = found[0] if found else name
    return out


def _suffix_axis(column: str, said: dict[str, str]) -> str | None:
    """The axis the unit suffix of `column` (the name given for q or u) says, or None."""
    quantity = next(k for k, v in said.items() if v == column)
    for suffix, axis in UNIT_SUFFIXES[quantity].items():
        if column.endswith(suffix) and column != quantity:
            return axis
    return None


def axis_of(said: dict[str, str], path: str | Path) -> str | None:
    """The axis the unit suffixes of the names given for `q` and `u` say (`said`:
    quantity -> column or variable name), or None where neither has one.

    Raises
    ------
    RecordingError
        The two suffixes say different axes (`q_rad` with `u_n`).
    """
    axes = {a for a in (_suffix_axis(v, said) for v in said.values()) if a is not None}
    if len(axes) > 1:
        raise RecordingError(
            f"recording {path}: {said['q']!r} and {said['u']!r} name different units "
            "(one a linear axis, the other a rotary one); expected q_m with u_n or q_rad "
            "with u_n_m"
        )
    return axes.pop() if axes else None


def recording_axis(
    path: str | Path, mat_columns: tuple[str, str, str] = ("t", "qm", "gtau*vir")
) -> str | None:
    """The axis a rigid-axis recording's unit suffixes say, from its header alone (or,
    for a `.mat` file, from the variable names given for q and u); None where none says,
    or where the file cannot be read (reading it reports why)."""
    path = Path(path)
    if path.suffix.lower() == ".mat":
        return axis_of({"q": mat_columns[1], "u": mat_columns[2]}, path)
    try:
        header = pd.read_csv(path, nrows=0).columns
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return axis_of(contract_columns([str(c).strip() for c in header], path), path)


def read_numeric_csv(
    path: Path, required: tuple[str, ...], names: dict[str, str] | None = None
) -> pd.DataFrame:
    """A CSV whose every column is numeric and finite, `t` strictly increasing at a
    plausible rate (`teleop_core.recording_checks`); one line naming the first problem
    otherwise. `names` receives, per quantity of `UNIT_SUFFIXES`, the column that holds
    it (`contract_columns`: `q_rad` for `q`); the frame has it under the contract's
    name."""
    frame = read_cells(path, RecordingError)
    said = contract_columns(list(frame.columns), path)
    if names is not None:
        names.update(said)
    frame = frame.rename(columns={v: k for k, v in said.items() if v != k})
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise RecordingError(
            f"recording {path}: column {missing[0]!r} missing; expected columns "
            f"{', '.join(required)} (other numeric columns are extra channels), found "
            f"{', '.join(frame.columns)}"
        )
    out = pd.DataFrame(
        {c: numbers(frame, c, f"recording {path}", RecordingError) for c in frame.columns}
    )
    _check_time(out["t"].to_numpy(float), str(path))
    return out


def _check_time(t: Float1D, name: str) -> None:
    check_time(t, f"recording {name}", RecordingError, MIN_ROWS)


_PRODUCT = re.compile(r"^\s*[A-Za-z_]\w*(\s*\*\s*[A-Za-z_]\w*)*\s*$")


def mat_to_frame(path: str | Path, *, q: str, u: str, t: str) -> pd.DataFrame:
    """A MATLAB v5 `.mat` recording in the rigid-axis contract.

    `q`, `u` and `t` name variables of the file, or products of them (`gtau*vir`: a
    vector times a scalar gain). Every other vector with as many samples becomes an
    extra channel under its own name; scalars (gains) are left out.
    """
    # lazy: scipy.io costs 19 ms at start-up
    from scipy.io import loadmat

    path = Path(path)
    if not path.is_file():  # loadmat's own message for a missing file is a format error
        raise RecordingError(f"recording {path}: no such file; expected a .mat file")
    try:
        raw = loadmat(path)
    except (ValueError, TypeError, OSError) as exc:
        raise RecordingError(f"recording {path} is not a readable MATLAB v5 file: {exc}") from None
    variables = {k: np.asarray(v) for k, v in raw.items() if not k.startswith("__")}

    def value(expr: str) -> Float1D:
        if not _PRODUCT.match(expr):
            raise RecordingError(f"{expr!r}; expected a variable name or a product like gtau*vir")
        out: Float1D | float = 1.0
        for name in (p.strip() for p in expr.split("*")):
            if name not in variables:
                raise RecordingError(
                    f"{path}: variable {name!r} not found; expected one of "
                    f"{', '.join(sorted(variables))}"
                )
            out = out * variables[name].astype(float).ravel()
        return np.asarray(out, float)

    columns = {"t": value(t), "q": value(q), "u": value(u)}
    n = len(columns["t"])
    for name, column in columns.items():
        if len(column) != n:
            raise RecordingError(f"{path}: {name} has {len(column)} samples; expected {n} like t")
    used = {p.strip() for e in (q, u, t) for p in e.split("*")}
    for name, v in variables.items():
        if name not in used and v.size == n and np.issubdtype(v.dtype, np.number):
            columns[name] = v.astype(float).ravel()
    frame = pd.DataFrame(columns)
    for name in frame.columns:  # the same cell checks as a CSV's
        numbers(frame, name, f"recording {path}", RecordingError, "sample", first_row=1)
    _check_time(frame["t"].to_numpy(float), str(path))
    return frame
