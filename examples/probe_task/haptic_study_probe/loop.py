"""The probe task's closed loop and simulated participant.

The medium resists with a viscous force, F = B v (B = `DAMPING_N_S_PER_M`), and the
dial sets the probe's speed by rate control, v = k_v * aim (as the LCCA dial's eq. 5),
so at the simulated participant's constant aim the peak push force has the closed form
B * k_v * aim and the completion time is depth / v (to the 10 ms sample). All values
are the example's own assumptions; nothing here is measured.
"""

from __future__ import annotations

import numpy as np

from teleop_core.loop.drivers import Driver, HandAction, OperatorView

DEPTH_M = 0.08
"""How deep the probe goes; reaching it ends the trial with success."""
DAMPING_N_S_PER_M = 40.0
"""B: the medium's viscous resistance."""
RATE_GAIN_M_S_PER_RAD = 0.05
"""k_v: probe speed per rad of the dial's aim."""
AIM_RAD = 0.8
"""The simulated participant's aim, the same in every trial."""
RATE_HZ = 100.0
"""Samples per second."""
COLUMNS = 10
"""Width of a sample row: `ProbeTask.sample_columns`, in their order."""


class ProbeDriver(Driver):
    """Aims the dial at a fixed angle until the probe is at depth."""

    rate_hz = 25.0

    def __init__(self, aim_rad: float = AIM_RAD) -> None:
        self.aim_rad = aim_rad

    def start(self, rng: np.random.Generator) -> None:
        pass

    def act(self, view: OperatorView) -> HandAction:
        return HandAction(done=True) if view.success else HandAction(dial_target_rad=self.aim_rad)


class ProbeLoop:
    """The task's loop: the dial's aim sets the probe's speed; the medium pushes back.

    Rows: t_s, depth_m, roll_rad, tip_x_m, tip_y_m, tip_z_m, where (region index),
    push_force_n, aim_rad, medium_speed_m_s.
    """

    def __init__(self, condition: str) -> None:
        self.condition = condition
        self.t_s, self.depth_m, self.done, self.success = 0.0, 0.0, False, False

    def start(self, driver: Driver) -> None:
        self.driver = driver
        driver.start(np.random.default_rng(0))

    def advance(self, duration_s: float) -> np.ndarray:
        rows = []
        for _ in range(round(duration_s * RATE_HZ)):
            if self.done:
                break
            view = OperatorView(
                self.t_s,
                0.0,
                0.0,
                self.depth_m,
                0.0,
                (self.depth_m, 0.0, 0.0),
                "medium",
                self.success,
            )
            action = self.driver.act(view)
            if action.done:
                self.done = True
                break
            # v = k_v * aim (rate control)
            speed = RATE_GAIN_M_S_PER_RAD * action.dial_target_rad
            self.t_s = round(self.t_s + 1 / RATE_HZ, 9)
            self.depth_m = min(self.depth_m + speed / RATE_HZ, DEPTH_M)
            self.success = self.depth_m >= DEPTH_M - 1e-12
            region = 1.0 if self.success else 0.0
            # F = B v
            force = DAMPING_N_S_PER_M * speed
            rows.append(
                [
                    self.t_s,
                    self.depth_m,
                    0.0,
                    self.depth_m,
                    0.0,
                    0.0,
                    region,
                    force,
                    action.dial_target_rad,
                    speed,
                ]
            )
        return np.array(rows, dtype=float).reshape(-1, COLUMNS)
