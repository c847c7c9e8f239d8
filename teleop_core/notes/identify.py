"""Characterisation of one NOTES axis from recordings: FRF, grey-box fit, ramp hysteresis.

Owns what the paper does in III with Matlab's System Identification toolbox, here with
scipy: the measured frequency responses V = V_ee/F_des (open end) and F = F_ee/F_des
(clamped) from chirp runs, the grey-box fit of the five Fig. 8 parameters to them, and
the static-ramp measures (continuous limit, hysteresis, direction asymmetry).

- Velocity: the position is differentiated (`np.gradient`) and low-passed at 30 Hz by a
  4th-order Butterworth (`scipy.signal.butter`, run forward and backward with
  `filtfilt`, so it adds no phase), as in III-B. The command goes through the same
  filter, so the ratio of the two is not biased by the filter's roll-off near 30 Hz.
- FRF: the whole-record Fourier ratio Y(f) / U(f) (`numpy.fft.rfft`) on the 1-30 Hz
  band; a chirp run that starts and ends at rest needs no window, and Welch averaging
  (`scipy.signal.csd`) was tried first and dropped: its segments cut a single sweep and
  bias the response by several percent. Each bin is weighted by its share of the
  input's energy times snr / (1 + snr), the noise measured in the run's quiet tail
  (`scipy.signal.welch`); bins with snr < `MIN_SNR` are left out.
- Fit: `scipy.optimize.least_squares` on the log of the parameters; the residual is the
  complex log ratio log(H_model / H_measured) (magnitude in natural-log units and
  phase in rad) weighted by the square root of the bin's weight. V alone identifies all
  five parameters (its DC gain is 1/b_m, and its three poles and zero fix the rest);
  F alone fixes only their ratios to M_m, so a clamped-only fit holds M_m and M_s at
  the starting values.
- Fit quality: Matlab's `compare` figure, 100 (1 - ||H - H_model|| / ||H - mean(H)||)
  on the complex response, per transfer function.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import optimize, signal

from teleop_core._typing import Float1D
from teleop_core.notes.params import CHIRP_BAND_HZ, MSD_FIELDS, MsdParams
from teleop_core.notes.recording import NotesRecording, NotesRecordingError
from teleop_core.notes.transfer import frequency_response

LOWPASS_HZ = 30.0
"""Cut-off of the velocity's Butterworth low-pass (III-B)."""
LOWPASS_ORDER = 4
"""Order of that filter (the paper does not give it; assumption)."""
TAIL_S = 0.5
"""Length of the quiet end of a run from which the noise is measured, s."""
MIN_SNR = 100.0
"""Bins whose output power is less than this many times the noise's are left out: the
log of a noisy ratio is biased at low signal-to-noise ratio."""
MIN_WEIGHT = 0.01
"""Bins with less than this share of the peak input energy are left out of the fit."""


@dataclass(frozen=True)
class Frf:
    """A measured frequency response on the chirp's band."""

    which: str
    """"V" (open end) or "F" (clamped)."""
    f_hz: Float1D
    """Frequencies, Hz, shape (n,)."""
    h: Float1D
    """Complex response, shape (n,)."""
    weight: Float1D
    """Relative input energy in (0, 1], the fit's weight, shape (n,)."""

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame(
            {
                "f_hz": self.f_hz,
                "magnitude": np.abs(self.h),
                "phase_rad": np.angle(self.h),
                "weight": self.weight,
            }
        )


def velocity_from_position(t: Float1D, x: Float1D, f_des: Float1D) -> tuple[Float1D, Float1D]:
    """(v, f_des) both low-passed at 30 Hz: v = filtered d x / d t (III-B)."""
    fs = 1.0 / float(np.median(np.diff(t)))
    if fs <= 2 * LOWPASS_HZ:
        raise NotesRecordingError(
            f"sampling rate {fs:.1f} Hz; expected above {2 * LOWPASS_HZ:.0f} Hz for the "
            "30 Hz low-pass"
        )
    sos = signal.butter(LOWPASS_ORDER, LOWPASS_HZ, fs=fs, output="sos")
    v = np.gradient(x, t)
    return signal.sosfiltfilt(sos, v), signal.sosfiltfilt(sos, f_des)


def _noise_energy(y: Float1D, u: Float1D, fs: float, f: Float1D) -> Float1D:
    """Expected |N(f)|^2 of the measurement noise in a whole-record FFT, from the quiet
    end of the run (the last `TAIL_S` with no command, after the response has died out:
    only noise is left). Zero when the run has no such tail or no noise."""
    quiet = np.flatnonzero(np.abs(u[::-1]) > 1e-12 * np.max(np.abs(u)))
    rest = quiet[0] if quiet.size else len(u)
    n_tail = int(TAIL_S * fs)
    if rest < 2 * n_tail:
        return np.zeros_like(f)
    tail = y[-n_tail:]
    f_psd, psd = signal.welch(tail - tail.mean(), fs=fs, nperseg=min(n_tail, 256))
    # one-sided density -> expected squared FFT magnitude of a length-N record
    return np.interp(f, f_psd, psd) * fs * len(y) / 2


def measure_frf(recording: NotesRecording) -> Frf:
    """The frequency response of a chirp recording (V if open-ended, F if clamped).

    Whole-record Fourier ratio Y(f) / U(f) (`numpy.fft.rfft`) on the 1-30 Hz band: a run
    that starts and ends at rest needs no window. Each bin's weight is its share of the
    input's energy (|U|^2 / max |U|^2) times snr / (1 + snr), the signal-to-noise ratio
    of |Y|^2 against the noise measured in the run's quiet tail (a coherence estimate);
    bins below `MIN_WEIGHT` are left out.
    """
    if recording.boundary == "open":
        y, u = velocity_from_position(recording.t, recording.y, recording.f_des)
        which = "V"
        u_raw = recording.f_des
    else:
        y, u = recording.y, recording.f_des
        which = "F"
        u_raw = u
    fs = recording.rate_hz
    # numpy's stubs type rfftfreq as floating[Any]; it returns float64
    f: Float1D = np.fft.rfftfreq(len(u), 1.0 / fs)  # type: ignore[assignment]
    uf, yf = np.fft.rfft(u - u.mean()), np.fft.rfft(y - y.mean())
    lo, hi = CHIRP_BAND_HZ
    band = (f >= lo) & (f <= hi)
    if not band.any():
        raise NotesRecordingError("chirp recording is too short to resolve 1-30 Hz")
    energy = np.abs(uf) ** 2
    noise = _noise_energy(y, u_raw, fs, f)
    snr = np.maximum(np.abs(yf) ** 2 / np.maximum(noise, 1e-300) - 1.0, 0.0)
    weight = energy / energy[band].max() * snr / (1.0 + snr)
    keep = band & (weight >= MIN_WEIGHT) & (snr >= MIN_SNR)
    if np.count_nonzero(keep) < 5:
        raise NotesRecordingError(
            f"chirp recording has {np.count_nonzero(keep)} usable frequencies in "
            f"{lo:g}-{hi:g} Hz; expected a 1-30 Hz chirp response above the noise"
        )
    # H = Y / U
    return Frf(which, f[keep], yf[keep] / uf[keep], weight[keep])


def fit_percent(frf: Frf, p: MsdParams) -> float:
    """Matlab's NRMSE fit, 100 (1 - ||H - H_model|| / ||H - mean H||), percent."""
    model = frequency_response(p, frf.which, frf.f_hz)
    return float(100.0 * (1 - np.linalg.norm(frf.h - model) / np.linalg.norm(frf.h - frf.h.mean())))


@dataclass
class GreyBoxFit:
    """Grey-box fit of the Fig. 8 parameters to measured V and/or F responses.

    Parameters
    ----------
    start : MsdParams
        Starting values (and the held values of M_m, M_s when only F is given).
    """

    start: MsdParams
    params_: MsdParams = field(init=False, repr=False)
    """The fitted parameters (set by `fit`)."""
    fit_percent_: dict[str, float] = field(default_factory=dict, init=False)
    free_: tuple[str, ...] = field(default=(), init=False)
    cost_: float = field(default=float("nan"), init=False)

    def fit(self, frfs: list[Frf]) -> GreyBoxFit:
        """Fit to the given responses; returns self with `params_` and `fit_percent_`."""
        kinds = {frf.which for frf in frfs}
        free = MSD_FIELDS if "V" in kinds else ("k_s", "b_m", "b_s")
        x0 = np.log([getattr(self.start, name) for name in free])

        def build(x: Float1D) -> MsdParams:
            return self.start.scaled(
                {n: float(np.exp(v)) / getattr(self.start, n) for n, v in zip(free, x, strict=True)}
            )

        def residual(x: Float1D) -> Float1D:
            p = build(x)
            parts = []
            for frf in frfs:
                # complex log ratio: log|H_m/H| + j (angle difference), weighted per bin
                r = np.log(frequency_response(p, frf.which, frf.f_hz) / frf.h)
                w = np.sqrt(frf.weight / frf.weight.sum())
                parts += [w * r.real, w * np.angle(np.exp(1j * r.imag))]
            return np.concatenate(parts)

        sol = optimize.least_squares(residual, x0, method="lm", x_scale="jac")
        self.params_ = build(sol.x)
        self.free_ = tuple(free)
        self.cost_ = float(sol.cost)
        self.fit_percent_ = {frf.which: fit_percent(frf, self.params_) for frf in frfs}
        return self


@dataclass(frozen=True)
class RampMeasures:
    """What a clamped static ramp shows (III-A, Figs. 6-7)."""

    max_continuous: float
    """Largest output in the positive direction, N or N m (the paper's 5.62 N, 190.05 N mm)."""
    min_output: float
    """Largest output in the negative direction (signed), N or N m."""
    hysteresis: float
    """Mean gap between the rising and falling branches at the same command, N or N m."""
    gain_positive: float
    """Slope of output over command on the positive loading branch, below the limit."""
    gain_negative: float
    """The same on the negative loading branch."""

    @property
    def asymmetry(self) -> float:
        """1 - gain_negative / gain_positive: the negative (CCW) transmission loss."""
        return 1.0 - self.gain_negative / self.gain_positive

    def to_dict(self) -> dict[str, float]:
        return {
            "max_continuous": self.max_continuous,
            "min_output": self.min_output,
            "hysteresis": self.hysteresis,
            "gain_positive": self.gain_positive,
            "gain_negative": self.gain_negative,
            "asymmetry": self.asymmetry,
        }


def ramp_measures(recording: NotesRecording, limit: float | None = None) -> RampMeasures:
    """Hysteresis, limit and per-direction gain of a clamped ramp recording.

    `limit` (N or N m) excludes commands at or above it from the gain and hysteresis
    (where the actuator saturates); default: 95 % of the largest positive output.
    """
    if recording.boundary != "clamped":
        raise NotesRecordingError("a static ramp is read from a clamped recording (f_ee)")
    u, y = recording.f_des, recording.y
    top = float(np.max(y))
    limit = 0.95 * top if limit is None else limit
    rising = np.gradient(u) > 0
    grid = np.linspace(max(u.min(), -limit), min(u.max(), limit), 200)
    branches = []
    for mask in (rising, ~rising):
        order = np.argsort(u[mask], kind="stable")
        branches.append(np.interp(grid, u[mask][order], y[mask][order]))
    hysteresis = float(np.mean(np.abs(branches[0] - branches[1])))
    gains = []
    # loading branches (moving away from zero): output = g u -/+ F_c, slope g
    for sel in (rising & (u > 0.2 * limit) & (u < limit), ~rising & (u < -0.2 * limit)):
        if np.count_nonzero(sel) < 2:
            gains.append(float("nan"))
            continue
        gains.append(float(np.polyfit(u[sel], y[sel], 1)[0]))
    return RampMeasures(top, float(np.min(y)), hysteresis, gains[0], gains[1])
