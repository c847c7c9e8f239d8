"""The loop's configuration (`LoopConfig`: rates, links and devices) and what a run gives
back (`LoopCounters`, `LoopResult`); `master_vector` packs a config into the kernel's
master parameters. `TeleopLoop` (`core.py`, which re-exports these) runs them."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from teleop_core.errors import TeleopInputError
from teleop_core.follower.params import (
    FollowerControlParams,
    FollowerPlantParams,
    FollowerSensorParams,
)
from teleop_core.loop import layout as K
from teleop_core.loop.layout import SAMPLE_COLUMNS
from teleop_core.loop.link import LinkParams
from teleop_core.master.params import DialParams, HapticParams

if TYPE_CHECKING:
    from teleop_core.estimation.model import ForceEstimator


@dataclass(frozen=True)
class LoopConfig:
    device_rate_hz: float = 1000.0
    """Device physics and master controller rate (IV-A)."""
    acquisition_rate_hz: float = 100.0
    """Hardware acquisition rate (IV-A)."""
    estimation_rate_hz: float = FollowerSensorParams.estimation_rate_hz
    """Estimation pipeline rate (IV-A)."""
    driver_rate_hz: float = 100.0
    """How often the driver decides."""
    to_follower: LinkParams = field(default_factory=LinkParams)
    """Master -> follower: rate and rotation commands."""
    to_master: LinkParams = field(default_factory=LinkParams)
    """Follower -> master: the force estimate."""
    haptics: HapticParams = field(default_factory=HapticParams)
    dial: DialParams = field(default_factory=DialParams)
    plant: FollowerPlantParams = field(default_factory=FollowerPlantParams)
    control: FollowerControlParams = field(default_factory=FollowerControlParams)
    sensors: FollowerSensorParams = field(default_factory=FollowerSensorParams)
    dial_encoder_counts_per_rev: int = 4096
    """The dial's AS5600 (IV-A)."""
    dial_velocity_filter_s: float = 0.002
    """Low-pass on the dial's differentiated angle for eq. 8's damper; assumption."""

    def __post_init__(self) -> None:
        ticks = {}
        for name in ("acquisition_rate_hz", "estimation_rate_hz", "driver_rate_hz"):
            ratio = self.device_rate_hz / getattr(self, name)
            if not (ratio >= 1 and abs(ratio - round(ratio)) < 1e-9):
                raise TeleopInputError(
                    f"{name} = {getattr(self, name)} does not divide device_rate_hz "
                    f"{self.device_rate_hz}; expected e.g. 100 of 1000"
                )
            ticks[name] = round(ratio)
        if ticks["estimation_rate_hz"] % ticks["acquisition_rate_hz"]:
            raise TeleopInputError(
                f"estimation_rate_hz {self.estimation_rate_hz} is not the acquisition rate "
                f"{self.acquisition_rate_hz} divided by a whole number"
            )
        if abs(self.device_rate_hz - self.control.speed_loop_rate_hz) > 1e-9:
            raise TeleopInputError(
                f"device_rate_hz {self.device_rate_hz} differs from the drive's speed loop "
                f"{self.control.speed_loop_rate_hz} Hz; expected them equal"
            )


@dataclass
class LoopCounters:
    """How many times each part ran (rate bookkeeping)."""

    ticks: int = 0
    acquisitions: int = 0
    estimates: int = 0
    driver_updates: int = 0
    commands_sent: int = 0
    forces_sent: int = 0


@dataclass
class LoopResult:
    """The 100 Hz samples of a run, the 1 kHz log if kept, and the counters."""

    samples: np.ndarray
    counters: LoopCounters
    branches: tuple[str, ...]
    ticks: np.ndarray | None = None
    success: bool = False
    done_s: float = math.nan

    def to_frame(self) -> pd.DataFrame:
        frame = pd.DataFrame(self.samples, columns=list(SAMPLE_COLUMNS))
        names = np.asarray(self.branches, dtype=object)
        frame["branch"] = names[self.samples[:, SAMPLE_COLUMNS.index("branch")].astype(int)]
        return frame

    def ticks_frame(self) -> pd.DataFrame:
        if self.ticks is None:
            raise TeleopInputError("this run kept no 1 kHz log; run with keep_ticks=True")
        return pd.DataFrame(self.ticks, columns=list(K.LOG_COLUMNS))


def master_vector(cfg: LoopConfig, estimator: ForceEstimator | None) -> np.ndarray:
    """The kernel's master parameters (`layout.M_*`) for a config and an estimator."""
    h, poly = cfg.haptics, cfg.dial.polynomials
    mp = np.zeros(K.MASTER_PARAM_SIZE)
    mp[K.M_KS], mp[K.M_BS], mp[K.M_THETA_REF] = (
        h.spring_n_m_per_rad,
        h.damper_n_m_s_per_rad,
        h.reference_angle_rad,
    )
    mp[K.M_GH], mp[K.M_DEADBAND], mp[K.M_SAT] = (
        h.haptic_gain_n_m_per_n,
        h.deadband_n,
        h.saturation_n_m,
    )
    mp[K.M_HAPTICS_ON] = 1.0 if h.haptics_on else 0.0
    mp[K.M_LEVER], mp[K.M_IMAX] = poly.lever_arm_m, poly.max_current_ma
    mp[K.M_ENC_STEP] = 2 * math.pi / cfg.dial_encoder_counts_per_rev
    mp[K.M_VEL_FILTER_S] = cfg.dial_velocity_filter_s
    mp[K.M_WHEEL_R] = cfg.plant.wheel_radius_m
    mp[K.M_IQ_FILTER_S] = cfg.sensors.current_filter_s
    mp[K.M_DT] = 1.0 / cfg.device_rate_hz
    mp[K.M_POLY : K.M_POLY_END] = [*poly.loading, *poly.unloading]
    mp[K.M_ACQ_EVERY] = round(cfg.device_rate_hz / cfg.acquisition_rate_hz)
    mp[K.M_EST_EVERY] = round(cfg.device_rate_hz / cfg.estimation_rate_hz)
    mp[K.M_KV] = h.speed_gain_m_s_per_rad
    mp[K.M_HAS_EST] = 1.0 if estimator is not None else 0.0
    mp[K.M_EST_DT] = estimator.dt_s if estimator is not None else 0.0
    return mp
