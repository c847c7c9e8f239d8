"""Simulated recordings carrying effects their base model lacks.

`follower_recording` drives the wheel through a random teleoperation session
(`scenarios.teleoperation`: advance, hold, withdraw against a phantom-like load),
computes the current the drive draws from eq. 1, and records as the force what eq. 1
plus the injected effects deliver for that current and motion (so effects that depend
on the current need no fixed-point iteration), with the sensor chain's noise on
current, speed and force. Without effects the recording
follows the base model exactly, so anything the loop adds to it is a false alarm.
Each effect's parameters are drawn from the seed, and its amplitude is set so that its
force over the whole recording has the RMS `size_n` (the JND, 0.192 N, by default);
`delay` has no amplitude, only a lag, and its size is what that lag makes it.

`master_recording` runs the simulated dial clamped on its calibration lever
(`master.dial.gauge_force`, with its hysteresis between eqs. 14 and 15 and the
gauge's lag) through up-and-down current sweeps in the calibrated 0-4 mA range.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from teleop_core._typing import Float1D
from teleop_core.calibration.effects import (
    EFFECTS,
    SIGN_SPEED_RAD_S,
    play_operator,
    smooth_sign,
)
from teleop_core.errors import TeleopInputError
from teleop_core.follower.physics import PhysicsParams
from teleop_core.follower.recording import FollowerRecording
from teleop_core.follower.scenarios import teleoperation
from teleop_core.master.dial import gauge_force
from teleop_core.master.params import DialParams

JND_N = 0.192
"""Just-noticeable difference of proximal force ([endovascular]), N."""


def _shape(
    family: str, p: dict[str, float], iq: Float1D, w: Float1D, theta: Float1D, t: Float1D
) -> Float1D:
    """Unit-amplitude force shape of an injected effect (N per unit of `scale`)."""
    if family == "stribeck":
        return -np.exp(-((w / p["stribeck_speed_rad_s"]) ** 2)) * smooth_sign(w)
    if family == "viscous_nonlinear":
        return -np.sign(w) * np.abs(w) ** p["exponent"]
    if family == "direction_asymmetry":
        return -np.minimum(smooth_sign(w), 0.0)
    if family == "position_periodic":
        return np.sin(2 * np.pi * theta / p["period_rad"] + p["phase_rad"])
    if family == "hysteresis":
        return play_operator(np.ascontiguousarray(iq), p["loop_half_width_a"])
    if family == "drift":
        return -iq * (1.0 - np.exp(-(t - t[0]) / p["time_constant_s"]))
    if family == "current_nonlinearity":
        return -(iq**3)
    raise TeleopInputError(f"no injected shape for {family!r}")  # pragma: no cover


def _draw(family: str, rng: np.random.Generator, duration_s: float) -> dict[str, float]:
    """Parameters of an injected effect, drawn from `rng`."""
    if family == "stribeck":
        return {"stribeck_speed_rad_s": float(rng.uniform(0.3, 1.5))}
    if family == "viscous_nonlinear":
        return {"exponent": float(rng.uniform(1.8, 2.6))}
    if family == "position_periodic":
        return {
            "period_rad": float(2 * np.pi / rng.uniform(5.0, 40.0)),
            "phase_rad": float(rng.uniform(0, 2 * np.pi)),
        }
    if family == "hysteresis":
        return {"loop_half_width_a": float(rng.uniform(0.03, 0.08))}
    if family == "delay":
        return {"lag_s": float(rng.uniform(0.03, 0.08))}
    if family == "drift":
        # a winding heats over minutes: still changing when the recording ends
        return {"time_constant_s": float(rng.uniform(0.4, 1.5) * duration_s)}
    return {}


def follower_recording(
    duration_s: float,
    effects: Sequence[str] = (),
    *,
    rate_hz: float = 100.0,
    size_n: float = JND_N,
    seed: int = 0,
    physics: PhysicsParams | None = None,
    sign_speed_rad_s: float = SIGN_SPEED_RAD_S,
    noise_free: dict[str, Float1D] | None = None,
) -> tuple[FollowerRecording, dict[str, dict[str, Any]]]:
    """A follower recording whose true model is eq. 1 plus `effects`.

    Parameters
    ----------
    duration_s
        Length, s.
    effects
        Families to inject (names of `effects.EFFECTS`), none for a clean recording.
    rate_hz
        Sampling rate, Hz.
    size_n
        RMS force of each injected effect over the recording, N (not for `delay`).
    seed
        Seed of the session, the effects' parameters and the noise.
    sign_speed_rad_s
        Width w_s of the drive's Coulomb step tanh(w / w_s), rad/s: by default eq. 1's
        0.3; a real drive's is sharper.
    noise_free
        A dict that receives the signals before the sensor noise (`t`, `drive`,
        `speed`, `angle`, `force`), for effects injected afterwards on the true motion.

    Returns
    -------
    The recording, and per injected family its drawn parameters, its `scale` (N per
    unit shape) and its actual `rms_n`.
    """
    unknown = [f for f in effects if f not in EFFECTS]
    if unknown:
        raise TeleopInputError(f"unknown effect {unknown[0]!r}; expected one of {list(EFFECTS)}")
    pp = physics or PhysicsParams()
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    omega, load = teleoperation(duration_s, rng, dt_s=dt)
    n = len(omega)
    t = np.arange(1.0, n + 1.0) * dt
    theta = np.cumsum(omega) * dt
    alpha = np.diff(omega, prepend=omega[0]) / dt
    truth = {f: _draw(f, rng, duration_s) for f in effects}
    r, kt = pp.wheel_radius_m, pp.torque_constant_n_m_per_a
    # K_t I_q = J theta_dd + b theta_d + tau_c sgn(theta_d) + r (F - F_0)   (eq. 1)
    torque = (
        pp.inertia_kg_m2 * alpha
        + pp.viscous_damping_n_m_s_per_rad * omega
        + pp.coulomb_friction_n_m * smooth_sign(omega, sign_speed_rad_s)
        + r * (load - pp.offset_n)
    )
    iq = torque / kt
    # The force the wheel delivers for that current and motion: eq. 1 plus the effects.
    f_true = load.copy()
    for family in (f for f in effects if f != "delay"):
        shape = _shape(family, truth[family], iq, omega, theta, t)
        scale = size_n / max(float(np.sqrt(np.mean(shape**2))), 1e-12)
        truth[family].update(scale=scale, rms_n=size_n)
        f_true += scale * shape
    if "delay" in effects:
        lagged = np.interp(t - truth["delay"]["lag_s"], t, f_true)
        truth["delay"]["rms_n"] = float(np.sqrt(np.mean((lagged - f_true) ** 2)))
        f_true = lagged
    iq_meas = iq + rng.normal(0.0, 0.006, n)
    omega_meas = omega + rng.normal(0.0, 0.01, n)
    f_ref = f_true + rng.normal(0.0, 0.008, n)
    name = "+".join(effects) or "clean"
    rec = FollowerRecording.from_arrays(t, iq_meas, theta, omega_meas, f_ref, name=name)
    if noise_free is not None:
        noise_free.update(t=t, drive=iq, speed=omega, angle=theta, force=f_true)
    return rec, truth


def master_recording(
    duration_s: float,
    *,
    rate_hz: float = 100.0,
    seed: int = 0,
    params: DialParams | None = None,
) -> tuple[Float1D, Float1D, Float1D]:
    """The dial clamped on the calibration lever through random up-and-down sweeps.

    Returns (t s, commanded current mA, gauge force N) at `rate_hz`.
    """
    params = params or DialParams()
    rng = np.random.default_rng(seed)
    dt = 1e-3
    top = params.polynomials.max_current_ma
    levels = [0.0]
    while len(levels) < duration_s:  # one turning point about every 1-4 s
        levels.append(float(rng.uniform(0.0, top)))
    knots = np.cumsum(np.r_[0.0, rng.uniform(1.0, 4.0, len(levels) - 1)])
    t_fine = np.arange(float(round(duration_s / dt))) * dt
    current_ma = np.interp(t_fine, knots, levels)
    force = gauge_force(params, current_ma / 1000.0, dt, rng)
    m = max(1, round(1.0 / (rate_hz * dt)))
    idx = np.arange(m - 1, len(t_fine), m)
    return t_fine[idx] + dt, current_ma[idx], force[idx]
