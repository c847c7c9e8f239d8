"""Simulated bench recordings of the NOTES device: ramps and chirps, open or clamped end.

Owns the time-domain model of one axis (the Fig. 8 masses, spring and dampers plus
Karnopp friction on the manipulator, the actuator's continuous limit and the
direction-dependent transmission) and the commands of the paper's two experiments
(III-A static ramps, III-B 1-30 Hz chirp). Its output is the recording CSV contract
(`recording.py`): `t, f_des, x` open-ended, `t, f_des, f_ee` clamped, SI units (rotation:
N m and rad), so simulated and measured data go through the same characterisation.

The step loop is a numba kernel (semi-implicit Euler at `SUBSTEPS` per sample): scipy's
`lsim` covers only the linear model, and Karnopp's stick/slip switch needs the state at
every step. Its linear part is tested against `scipy.signal.lsim` of the transfer
functions in `transfer.py`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from scipy import signal

from teleop_core._jit import njit
from teleop_core._typing import Float1D
from teleop_core.notes.karnopp import (
    COMP_COULOMB,
    COMP_GAIN_NEG,
    COMP_GAIN_POS,
    COMP_ON,
    compensated_command,
)
from teleop_core.notes.params import (
    CHIRP_BAND_HZ,
    MSD_B_M,
    MSD_B_S,
    MSD_K_S,
    MSD_M_M,
    MSD_M_S,
    AxisParams,
    NotesParamsError,
)

if TYPE_CHECKING:
    from teleop_core.notes.compensation import KarnoppCompensator

BOUNDARIES = ("open", "clamped")
RATE_HZ = 1000.0
"""Sampling rate of the simulated bench (the DAQ's rate is not given; assumption)."""
SUBSTEPS = 50
"""Integration steps per sample (20 us at 1 kHz): semi-implicit Euler shifts a damper by
about k h / 2, 0.7 % of the translational b_s at this step (the fastest mode is ~100 rad/s)."""
RAMP_RANGE = {"translation": (6.0, -4.0), "rotation": (0.190, -0.190)}
"""Commanded extremes of the static ramps: +6 to -4 N (Fig. 6), +/-190 N mm (Fig. 7)."""
RAMP_DURATION_S = {"translation": 20.0, "rotation": 20.0}
"""Length of one ramp 0 -> max -> min -> 0; slow enough to be quasi-static (assumption)."""
CHIRP_AMPLITUDE = {"translation": 4.5, "rotation": 0.15}
"""Chirp amplitude, N or N m; within the continuous limits (assumption)."""
CHIRP_FADE_S = 0.5
"""Fade-in and fade-out of the chirp's amplitude, s (assumption)."""
CHIRP_TAIL_S = 1.0
"""Rest after the chirp, so the response has died out when the recording ends and the
whole-record Fourier ratio is the frequency response (assumption)."""
STICK_VELOCITY = {"translation": 1.0e-4, "rotation": 1.0e-3}
"""Karnopp's stick band on the manipulator's speed, m/s or rad/s (assumption)."""


def ramp_command(dof: str, rate_hz: float = RATE_HZ) -> tuple[Float1D, Float1D]:
    """The static-ramp command 0 -> max -> min -> 0 of `dof`: (t in s, f_des), shape (n,)."""
    hi, lo = RAMP_RANGE[dof]
    duration = RAMP_DURATION_S[dof]
    t = np.arange(0.0, duration, 1.0 / rate_hz)
    # piecewise-linear through the corners, time shared in proportion to the travel
    travel = np.cumsum([0.0, hi, hi - lo, -lo])
    corners_t = duration * travel / travel[-1]
    return t, np.interp(t, corners_t, [0.0, hi, lo, 0.0])


def chirp_command(
    dof: str, rate_hz: float = RATE_HZ, duration_s: float = 20.0, amplitude: float | None = None
) -> tuple[Float1D, Float1D]:
    """A logarithmic 1-30 Hz chirp (`scipy.signal.chirp`) of `dof` followed by
    `CHIRP_TAIL_S` at rest: (t in s, f_des), shape (n,)."""
    amp = CHIRP_AMPLITUDE[dof] if amplitude is None else amplitude
    t = np.arange(0.0, duration_s + CHIRP_TAIL_S, 1.0 / rate_hz)
    f0, f1 = CHIRP_BAND_HZ
    u = amp * signal.chirp(t, f0, duration_s, f1, method="logarithmic", phi=-90)
    # half-second cosine fade-in and -out, so the force's net impulse (the open end's
    # drift) is near zero; it leaves the 1-30 Hz band's spectrum almost untouched
    n = round(duration_s * rate_hz)
    taper = signal.windows.tukey(n, alpha=2 * CHIRP_FADE_S / duration_s)
    return t, np.concatenate([u[:n] * taper, np.zeros(len(t) - n)])


@njit(cache=True)
def _simulate_axis(
    f_des: np.ndarray,
    dt: float,
    substeps: int,
    lin: np.ndarray,
    coulomb: float,
    static: float,
    gain_pos: float,
    gain_neg: float,
    saturation: float,
    stick_velocity: float,
    clamped: bool,
    comp: np.ndarray,
) -> np.ndarray:
    m_m, m_s, k_s = lin[MSD_M_M], lin[MSD_M_S], lin[MSD_K_S]
    b_m, b_s = lin[MSD_B_M], lin[MSD_B_S]
    h = dt / substeps
    x_m = v_m = x_s = v_s = 0.0
    out = np.empty(f_des.shape[0])
    u_prev = 0.0
    for i in range(f_des.shape[0]):
        u = f_des[i]
        if comp[COMP_ON] > 0.0:
            coulomb_c, gain_pos_c, gain_neg_c = (
                comp[COMP_COULOMB],
                comp[COMP_GAIN_POS],
                comp[COMP_GAIN_NEG],
            )
            u = compensated_command(
                u, u - u_prev, v_m, stick_velocity, coulomb_c, gain_pos_c, gain_neg_c
            )
        u_prev = f_des[i]
        # transmitted command: direction-dependent gain, then the actuator's limit
        f_act = u * (gain_pos if u >= 0.0 else gain_neg)
        f_act = min(max(f_act, -saturation), saturation)
        for j in range(substeps):
            if j == substeps // 2:
                # sampled mid-hold: cancels the zero-order hold's half-sample delay
                out[i] = k_s * x_m + b_s * v_m if clamped else x_s
            # spring and damper force on the scope (= load-cell force when clamped)
            f_c = k_s * (x_m - x_s) + b_s * (v_m - v_s)
            f_net = f_act - b_m * v_m - f_c
            # Karnopp: inside the stick band friction cancels the net force up to breakaway
            if abs(v_m) < stick_velocity:
                if abs(f_net) <= static:
                    f_fric = f_net
                    v_m = 0.0
                else:
                    f_fric = coulomb * np.sign(f_net)
            else:
                f_fric = coulomb * np.sign(v_m)
            v_m += h * (f_net - f_fric) / m_m
            x_m += h * v_m
            if not clamped:
                v_s += h * f_c / m_s
                x_s += h * v_s
    return out


def simulate_response(
    params: AxisParams,
    t: Float1D,
    f_des: Float1D,
    boundary: str,
    nonlinear: bool = True,
    compensator: KarnoppCompensator | None = None,
) -> Float1D:
    """The noise-free measured signal for a command sampled uniformly at `t`.

    Parameters
    ----------
    params : TranslationParams or RotationParams
    t : (n,) float, s; uniformly spaced.
    f_des : (n,) float, N or N m; the commanded force or torque (held over each sample).
    boundary : "open" (returns the scope position x, m or rad) or "clamped" (returns
        the load-cell force f_ee, N or N m).
    nonlinear : False simulates the linear Fig. 8 model only (no friction, unit
        transmission, no saturation).
    compensator : a fitted `KarnoppCompensator` between the command and the motors, or
        None for the uncompensated device.
    """
    if boundary not in BOUNDARIES:
        raise NotesParamsError(f"boundary {boundary!r}; expected one of {', '.join(BOUNDARIES)}")
    # lazy: teleop_core.notes.compensation costs 8 ms at start-up
    from teleop_core.notes.compensation import NO_COMPENSATION

    p = params if nonlinear else params.without_nonlinearities()
    saturation = p.max_continuous + p.coulomb if nonlinear else np.inf
    dt = float(t[1] - t[0])
    gain_pos, gain_neg = p.gains
    return _simulate_axis(
        np.ascontiguousarray(f_des, dtype=np.float64),
        dt,
        SUBSTEPS,
        np.array(p.linear.as_tuple()),
        p.coulomb,
        p.static,
        gain_pos,
        gain_neg,
        saturation,
        STICK_VELOCITY[p.dof],
        boundary == "clamped",
        NO_COMPENSATION if compensator is None else compensator.as_array(),
    )


def simulate_recording(
    params: AxisParams,
    experiment: str,
    boundary: str,
    *,
    nonlinear: bool = True,
    noise: float = 0.0,
    seed: int = 0,
    rate_hz: float = RATE_HZ,
    chirp_duration_s: float = 20.0,
) -> pd.DataFrame:
    """A simulated bench recording in the CSV contract.

    Parameters
    ----------
    params : TranslationParams or RotationParams
    experiment : "ramp" (III-A static ramp) or "chirp" (III-B 1-30 Hz chirp).
    boundary : "open" (columns t, f_des, x) or "clamped" (columns t, f_des, f_ee).
    nonlinear : friction, transmission asymmetry and saturation on (True) or the linear
        Fig. 8 model only (False).
    noise : sensor noise, standard deviation as a fraction of the clean signal's
        standard deviation (0.02 = 2 %), Gaussian from `np.random.default_rng(seed)`.
    seed : seeds the noise.
    rate_hz : sampling rate, Hz.
    chirp_duration_s : length of the chirp, s.

    Returns
    -------
    DataFrame with columns t (s), f_des (N or N m) and x (m or rad) or f_ee (N or N m).
    """
    if experiment == "ramp":
        t, f_des = ramp_command(params.dof, rate_hz)
    elif experiment == "chirp":
        t, f_des = chirp_command(params.dof, rate_hz, chirp_duration_s)
    else:
        raise NotesParamsError(f"experiment {experiment!r}; expected ramp or chirp")
    if not (np.isfinite(noise) and noise >= 0):
        raise NotesParamsError(f"noise {noise!r}; expected a fraction >= 0")
    y = simulate_response(params, t, f_des, boundary, nonlinear)
    if noise > 0:
        rng = np.random.default_rng(seed)
        y = y + rng.normal(0.0, noise * float(np.std(y)), size=y.shape)
    column = "x" if boundary == "open" else "f_ee"
    return pd.DataFrame({"t": t, "f_des": f_des, column: y})
