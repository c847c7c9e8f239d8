"""Transfer functions of the Fig. 8 model, derived from the mechanics ([notes], III-B).

The model (one axis; x_m manipulator, x_s scope, F the actuator's force F_des)::

    M_m x_m'' = F - b_m x_m' - k_s (x_m - x_s) - b_s (x_m' - x_s')
    M_s x_s'' =     k_s (x_m - x_s) + b_s (x_m' - x_s') - F_hand

Laplace, zero initial state; write Z_m = M_m s^2 + (b_m + b_s) s + k_s,
Z_s = M_s s^2 + b_s s + k_s and C = b_s s + k_s (the coupling).

Open end (the hand applies nothing, F_hand = 0)::

    [Z_m  -C ] [X_m]   [F]
    [-C   Z_s] [X_s] = [0]      =>  X_s / F = C / (Z_m Z_s - C^2)

    Z_m Z_s - C^2 = s D(s),
    D(s) = M_m M_s s^3 + (M_m b_s + M_s (b_m + b_s)) s^2
           + ((M_m + M_s) k_s + b_m b_s) s + b_m k_s

so the end-effector velocity response is

    V(s) = V_ee / F_des = s X_s / F = (b_s s + k_s) / D(s).

Clamped end (x_s = 0; the load cell reads the force the spring and damper put on the
scope, F_ee = k_s x_m + b_s x_m')::

    X_m / F = 1 / Z_m   =>   F(s) = F_ee / F_des = (b_s s + k_s) / (M_m s^2 + (b_m + b_s) s + k_s)

F(0) = 1: a clamped device at DC passes all its force to the load cell, and at high
frequency F(s) ~ b_s / (M_m s) falls at 20 dB/decade. The paper's printed F(s),
k_s / (s * [M_m M_s s^3 + ... + b_m k_s]), has a pure integrator and so an infinite DC
gain, which a force/force ratio of a clamped device cannot have: it is the open-end
*position* response X_s / F_des = C / (s D(s)) with C ~ k_s (the s^2 coefficient is
printed with 2 b_m b_s where the algebra gives b_m b_s). The paper's V(s),
1 / ((M_m + M_s) s + b_m + b_s), is the rigid limit k_s -> infinity of ours up to the
damping term (the rigid limit gives b_m alone).

Device impedance, as the paper defines it (eq. 3: F(s) = Z_device V(s))::

    Z_device(s) = F(s) / V(s) = D(s) / (M_m s^2 + (b_m + b_s) s + k_s)

This is the Thevenin output impedance of the device seen from the hand, blocked force
over free velocity. Limits: Z_device(0) = b_m k_s / k_s = b_m (the manipulator damping,
what a hand moving slowly feels) and Z_device(s) ~ M_s s at high frequency (the scope
mass, the spring isolating the manipulator).

Coefficients are kept as numpy polynomials (highest power first, scipy.signal's
convention); responses use `scipy.signal.freqs`, steps `scipy.signal.step`.
"""

from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.optimize import brentq

from teleop_core._typing import Float1D
from teleop_core.notes.params import MsdParams

Poly = tuple[Float1D, Float1D]
"""(numerator, denominator) coefficients, highest power of s first."""


def _d_poly(p: MsdParams) -> Float1D:
    m_m, m_s, k_s, b_m, b_s = p.as_tuple()
    # D(s) = M_m M_s s^3 + (M_m b_s + M_s (b_m + b_s)) s^2 + ((M_m + M_s) k_s + b_m b_s) s + b_m k_s
    return np.array(
        [m_m * m_s, m_m * b_s + m_s * (b_m + b_s), (m_m + m_s) * k_s + b_m * b_s, b_m * k_s]
    )


def _zm_poly(p: MsdParams) -> Float1D:
    # Z_m = M_m s^2 + (b_m + b_s) s + k_s
    return np.array([p.m_m, p.b_m + p.b_s, p.k_s])


def velocity_tf(p: MsdParams) -> Poly:
    """V(s) = V_ee / F_des = (b_s s + k_s) / D(s), open end (m/s per N or rad/s per N m)."""
    return np.array([p.b_s, p.k_s]), _d_poly(p)


def force_tf(p: MsdParams) -> Poly:
    """F(s) = F_ee / F_des = (b_s s + k_s) / (M_m s^2 + (b_m + b_s) s + k_s), clamped end."""
    return np.array([p.b_s, p.k_s]), _zm_poly(p)


def impedance_tf(p: MsdParams) -> Poly:
    """Z_device(s) = F(s) / V(s) = D(s) / (M_m s^2 + (b_m + b_s) s + k_s) (N s/m or N m s/rad)."""
    return _d_poly(p), _zm_poly(p)


TRANSFER_FUNCTIONS = {"V": velocity_tf, "F": force_tf, "Z": impedance_tf}


def frequency_response(p: MsdParams, which: str, f_hz: Float1D) -> Float1D:
    """Complex response of "V", "F" or "Z" at the frequencies `f_hz` (Hz), shape (n,)."""
    num, den = TRANSFER_FUNCTIONS[which](p)
    _, h = signal.freqs(num, den, worN=2 * np.pi * np.asarray(f_hz, dtype=float))
    return h


def force_bandwidth_hz(p: MsdParams, f_max_hz: float = 1000.0) -> float:
    """Lowest frequency at which |F(j 2 pi f)| falls 3 dB below its DC value of 1, Hz.

    Found on a fine logarithmic grid and refined with `scipy.optimize.brentq`.
    """

    f = np.logspace(-2, np.log10(f_max_hz), 4000)
    gap = np.abs(frequency_response(p, "F", f)) - 1 / np.sqrt(2)
    below = np.flatnonzero(gap < 0)
    if len(below) == 0:
        return float("inf")
    i = below[0]
    if i == 0:
        return float(f[0])

    def g(x: float) -> float:
        return float(np.abs(frequency_response(p, "F", np.array([x]))[0]) - 1 / np.sqrt(2))

    return float(brentq(g, f[i - 1], f[i]))


def settling_time_s(p: MsdParams, band: float = 0.02, horizon_s: float = 2.0) -> float:
    """2 % settling time of the clamped force's step response F(s) / s, s.

    The last time the response is outside 1 +/- `band` (F(0) = 1), from
    `scipy.signal.step` on a 0.1 ms grid.
    """
    t = np.arange(0.0, horizon_s, 1e-4)
    _, y = signal.step(force_tf(p), T=t)
    return step_settling_time_s(t, y, 1.0, band)


def step_settling_time_s(t: Float1D, y: Float1D, final: float, band: float = 0.02) -> float:
    """First time after which `y` stays within `final` (1 +/- `band`), s (t from the step)."""
    outside = np.flatnonzero(np.abs(y - final) > band * abs(final))
    if len(outside) == 0:
        return float(t[0])
    if outside[-1] + 1 >= len(t):
        return float("inf")
    return float(t[outside[-1] + 1])
