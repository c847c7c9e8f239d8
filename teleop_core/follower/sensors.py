"""The paper's sensor chain between the simulated drive and a recording ([endovascular], IV-A).

The ESP32 unit samples at the 100 Hz acquisition rate: the q-axis current through the
INA240 (low-passed by the firmware as SimpleFOC does, plus ADC noise), the
AS5600 angle (12-bit, unwrapped), and the firmware's velocity estimate. The bench adds
the DYLY-109 load cell as the reference force and, for velocity validation, the
2000 P/R quadrature encoder (Table I).
"""

from __future__ import annotations

import math

import numpy as np

from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError
from teleop_core.follower.params import FollowerSensorParams
from teleop_core.follower.plant import DriveTrace
from teleop_core.follower.recording import FollowerRecording


def quantise(angle_rad: Float1D, counts_per_rev: int) -> Float1D:
    """An encoder's reading of `angle_rad`: whole counts of 2 pi / counts_per_rev."""
    step = 2 * math.pi / counts_per_rev
    return np.floor(angle_rad / step) * step


def lowpass(x: Float1D, tau_s: float, dt_s: float) -> Float1D:
    """First-order low-pass y += dt/(tau + dt) (x - y), started at x[0] (tau 0: no filter)."""
    if tau_s == 0:
        return np.asarray(x, float).copy()
    import scipy.signal  # only for whole recordings (0.8 s to import)

    return scipy.signal.lfilter(
        [dt_s / (tau_s + dt_s)],
        [1.0, -tau_s / (tau_s + dt_s)],
        x,
        zi=[x[0] * tau_s / (tau_s + dt_s)],
    )[0]


def decimation(trace: DriveTrace, rate_hz: float) -> int:
    """How many device ticks make one acquisition period at `rate_hz`."""
    tick = float(trace.t_s[1] - trace.t_s[0])
    ratio = 1.0 / (rate_hz * tick)
    if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
        raise TeleopInputError(
            f"acquisition rate {rate_hz} Hz does not divide the device rate {1 / tick:.6g} Hz"
        )
    return round(ratio)


def acquire(
    trace: DriveTrace,
    sensors: FollowerSensorParams,
    rng: np.random.Generator,
    name: str = "simulated",
) -> FollowerRecording:
    """Sample a drive trace as the ESP32 and the bench's load cell would.

    Returns a recording at `sensors.acquisition_rate_hz` with the columns of the CSV
    contract; `alpha` is derived from `omega` as for a real recording.
    """
    m = decimation(trace, sensors.acquisition_rate_hz)
    n = len(trace.t_s) // m
    idx = np.arange(1, n + 1) * m - 1
    iq_filtered = lowpass(trace.iq_a, sensors.current_filter_s, float(trace.t_s[1] - trace.t_s[0]))
    iq = iq_filtered[idx] + rng.normal(0.0, sensors.current_noise_a, n)
    theta = quantise(trace.theta_rad[idx], sensors.encoder_counts_per_rev)
    omega = trace.omega_est_rad_s[idx]
    f_ref = trace.load_force_n[idx] + rng.normal(0.0, sensors.force_sensor_noise_n, n)
    return FollowerRecording.from_arrays(trace.t_s[idx], iq, theta, omega, f_ref, name=name)


def reference_velocity(trace: DriveTrace, sensors: FollowerSensorParams) -> tuple[Float1D, Float1D]:
    """Speed from the external 2000 P/R encoder at the acquisition rate: (t, omega)."""
    m = decimation(trace, sensors.acquisition_rate_hz)
    n = len(trace.t_s) // m
    idx = np.arange(1, n + 1) * m - 1
    angle = quantise(trace.theta_rad[idx], sensors.reference_encoder_counts_per_rev)
    period = m * float(trace.t_s[1] - trace.t_s[0])
    omega = np.diff(angle, prepend=angle[0]) / period
    return trace.t_s[idx], omega
