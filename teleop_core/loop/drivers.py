"""Who turns the dial and the rotation joystick: one interface for every driver.

A driver is asked, at the driver rate (100 Hz by default), what its hand does until the
next call, given what the person at the console perceives (`OperatorView`): the time,
the dial under the hand and the screen (the guidewire's insertion and rotation, the tip
and branch when the environment draws them). The view never carries the condition
label or the true force: in HV the only trace of the force is the torque the dial puts
on the hand, which shows as the dial lagging the hand's aim (`dial_angle_rad`).

The hand is a stiffness and damping about an aimed angle plus a push (`HandAction`);
the loop integrates it at the device rate inside the dial's dynamics, as the arm's
passive impedance acts faster than any decision. A grip stiffness of 0 is the hand off
the dial, which then returns to centre on its virtual spring (eq. 8).

Drivers: `SimulatedOperator` (a scripted reach used by the benches; the study's
simulated participants build on it), `KeyboardDriver` (key presses from the TUI) and
`teleop_core.loop.hardware.HardwareDriver` (the real dial on its ESP32).
"""

from __future__ import annotations

import math
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from teleop_core.errors import TeleopInputError


@dataclass(frozen=True)
class OperatorView:
    """What the operator perceives at one driver update."""

    t_s: float
    dial_angle_rad: float
    dial_speed_rad_s: float
    insertion_m: float
    rotation_rad: float
    tip_m: tuple[float, float, float]
    branch: str
    success: bool


@dataclass(frozen=True, init=False)
class HandAction:
    """The hand on the dial and the joystick until the next driver update."""

    dial_target_rad: float = 0.0
    """The angle the hand aims the dial at."""
    grip_stiffness_n_m_per_rad: float = 0.0
    """The hand's stiffness about that angle; 0 = hand off the dial."""
    grip_damping_n_m_s_per_rad: float = 0.0
    push_n_m: float = 0.0
    """A torque the hand adds (positive clockwise)."""
    rotation_rate_rad_s: float = 0.0
    """The rotation joystick: guidewire rotation speed."""
    done: bool = False
    """The operator ends the trial."""

    def __init__(
        self,
        dial_target_rad: float = 0.0,
        grip_stiffness_n_m_per_rad: float = 0.0,
        grip_damping_n_m_s_per_rad: float = 0.0,
        push_n_m: float = 0.0,
        rotation_rate_rad_s: float = 0.0,
        done: bool = False,
    ) -> None:
        # The fields written into the instance's dict at once (the same instance): the
        # generated __init__ of a frozen dataclass sets each through object.__setattr__,
        # a cost every driver update pays
        self.__dict__.update(
            dial_target_rad=dial_target_rad,
            grip_stiffness_n_m_per_rad=grip_stiffness_n_m_per_rad,
            grip_damping_n_m_s_per_rad=grip_damping_n_m_s_per_rad,
            push_n_m=push_n_m,
            rotation_rate_rad_s=rotation_rate_rad_s,
            done=done,
        )
        values = (
            dial_target_rad,
            grip_stiffness_n_m_per_rad,
            grip_damping_n_m_s_per_rad,
            push_n_m,
            rotation_rate_rad_s,
        )
        if not all(map(math.isfinite, values)):
            raise TeleopInputError(f"hand action {self}; expected finite values")
        if grip_stiffness_n_m_per_rad < 0 or grip_damping_n_m_s_per_rad < 0:
            raise TeleopInputError(f"hand action {self}; expected grip stiffness and damping >= 0")


RELEASED = HandAction()
GRIP_STIFFNESS_N_M_PER_RAD = 0.3
"""Finger grip on a 40 mm knob; assumption (wrist rotational stiffness is ~1-5 N m/rad,
the fingers on a small knob an order of magnitude less)."""
GRIP_DAMPING_N_M_S_PER_RAD = 3.0e-3
"""Assumption, near-critical damping of the grip on the dial's inertia."""


class DriverFailure(RuntimeError):
    """The driver's device failed in the middle of a trial (it stopped answering, was
    unplugged, or answered twice what the protocol does not allow): the trial cannot go on."""


class Driver(ABC):
    """Whoever turns the dial and the joystick."""

    physical_dial = False
    """True when the dial is real hardware (the loop then reads it instead of simulating it)."""
    realtime = False
    """True when the loop must keep pace with the wall clock (a person at real hardware)."""
    rate_hz: float | None = None
    """How often this driver decides; None takes the loop's `driver_rate_hz`."""

    def start(self, rng: np.random.Generator) -> None:  # noqa: B027 - optional hook
        """Called once before the first action with the loop's generator."""

    @abstractmethod
    def act(self, view: OperatorView) -> HandAction:
        """The hand's action until the next update."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Called once when the trial ends, however it ends (a device is let go)."""

    def record(self) -> dict[str, str | int]:
        """What the trial's summary keeps of this driver (a device's firmware, the
        lines it garbled); empty by default."""
        return {}


@dataclass
class SimulatedOperator(Driver):
    """A scripted operator: advance to a depth at a preferred speed, then let go.

    Aims the dial at the angle that would give the preferred speed (knowing k_v roughly,
    `speed_gain_guess_m_s_per_rad`), slowing in proportion over the last
    `approach_m`; reacts to the screen after `reaction_s`. Holds the dial with a finger
    grip, so a haptic torque deflects the dial and slows the guidewire.
    """

    target_depth_m: float = 0.25
    preferred_speed_m_s: float = 0.02
    approach_m: float = 0.03
    reaction_s: float = 0.15
    speed_gain_guess_m_s_per_rad: float = 0.05
    release_after_s: float = math.inf
    grip_stiffness_n_m_per_rad: float = GRIP_STIFFNESS_N_M_PER_RAD
    grip_damping_n_m_s_per_rad: float = GRIP_DAMPING_N_M_S_PER_RAD
    rate_hz: float | None = 50.0

    def start(self, rng: np.random.Generator) -> None:
        self._seen: list[tuple[float, float]] = []

    def act(self, view: OperatorView) -> HandAction:
        self._seen.append((view.t_s, view.insertion_m))
        # what the screen showed reaction_s ago
        while len(self._seen) > 1 and self._seen[1][0] <= view.t_s - self.reaction_s:
            self._seen.pop(0)
        seen_depth = self._seen[0][1]
        if view.success or view.t_s >= self.release_after_s:
            return HandAction(done=view.success)
        remaining = self.target_depth_m - seen_depth
        speed = self.preferred_speed_m_s * max(min(remaining / self.approach_m, 1.0), -1.0)
        return HandAction(
            dial_target_rad=speed / self.speed_gain_guess_m_s_per_rad,
            grip_stiffness_n_m_per_rad=self.grip_stiffness_n_m_per_rad,
            grip_damping_n_m_s_per_rad=self.grip_damping_n_m_s_per_rad,
        )


class KeyboardDriver(Driver):
    """Keys turn the dial and the joystick (the TUI feeds `press`).

    - "advance" / "retract" move the hand's aim by `step_rad` (held until changed);
    - "release" lets go of the dial (it self-centres) and zeroes the aim;
    - "rotate_cw" / "rotate_ccw" turn the joystick for `rotation_hold_s` (a terminal
      has no key-up events; auto-repeat keeps it turning while the key is held);
    - "stop" ends the trial.
    In HV the dial pushes back on the grip, so the same key presses give a smaller angle.
    """

    KEYS = ("advance", "retract", "release", "rotate_cw", "rotate_ccw", "stop")

    def __init__(
        self,
        step_rad: float = 0.1,
        max_angle_rad: float = 1.2,
        rotation_rate_rad_s: float = math.pi / 2,
        rotation_hold_s: float = 0.25,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.step_rad = step_rad
        self.max_angle_rad = max_angle_rad
        self.rotation_rate_rad_s = rotation_rate_rad_s
        self.rotation_hold_s = rotation_hold_s
        self._clock = clock
        self._lock = threading.Lock()
        self._aim = 0.0
        self._holding = False
        self._rotation = 0.0
        self._rotation_until = -math.inf
        self._stop = False

    def press(self, key: str) -> None:
        """Register a key (one of KEYS); unknown keys are refused."""
        if key not in self.KEYS:
            raise TeleopInputError(f"unknown key action {key!r}; expected one of {self.KEYS}")
        with self._lock:
            if key in ("advance", "retract"):
                step = self.step_rad if key == "advance" else -self.step_rad
                limit = self.max_angle_rad
                self._aim = min(max(self._aim + step, -limit), limit)
                self._holding = True
            elif key == "release":
                self._aim, self._holding = 0.0, False
            elif key == "stop":
                self._stop = True
            else:
                sign = 1.0 if key == "rotate_cw" else -1.0
                self._rotation = sign * self.rotation_rate_rad_s
                self._rotation_until = self._clock() + self.rotation_hold_s

    @property
    def aim_rad(self) -> float:
        return self._aim

    def act(self, view: OperatorView) -> HandAction:
        with self._lock:
            rotation = self._rotation if self._clock() < self._rotation_until else 0.0
            if not self._holding:
                return HandAction(rotation_rate_rad_s=rotation, done=self._stop)
            return HandAction(
                dial_target_rad=self._aim,
                grip_stiffness_n_m_per_rad=GRIP_STIFFNESS_N_M_PER_RAD,
                grip_damping_n_m_s_per_rad=GRIP_DAMPING_N_M_S_PER_RAD,
                rotation_rate_rad_s=rotation,
                done=self._stop,
            )
