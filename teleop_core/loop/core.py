"""`TeleopLoop`: the dial, the follower and the estimator at their own rates, joined by a link.

Rates ([endovascular], IV-A): device physics and the master controller at 1 kHz (the compiled
tick in `kernel.py`), acquisition at 100 Hz (the drive's ESP32 samples current, angle
and speed; the master reads the dial and sends the rate command), estimation at 50 Hz
(physics + GRU + EKF on the 100 Hz samples, every other one), the driver at 100 Hz.
Time is kept in whole ticks, so no rate drifts against another.

Where the estimate is computed: next to the drive, and the estimate crosses the link
(the paper runs the GRU on the master laptop and sends the samples instead; the delay
between the force and the dial is the same either way, and this way the link carries
what the latency bench measures). Without an estimator the loop publishes the true
proximal force (an ideal sensor), which isolates the loop from the estimator in tests.

A `LoopResult` holds the 100 Hz samples with the columns the database stores
(`layout.SAMPLE_COLUMNS`); `LoopConfig` and the results are in `config.py`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from teleop_core.errors import TeleopInputError
from teleop_core.estimation.model import ForceEstimator
from teleop_core.estimation.stream import EST_FINAL, NO_STREAM_ARRAYS
from teleop_core.follower.plant import STATE_SIZE, THETA, _param_vector
from teleop_core.loop import layout as K
from teleop_core.loop.config import LoopConfig, LoopCounters, LoopResult, master_vector
from teleop_core.loop.drivers import Driver, HandAction, OperatorView
from teleop_core.loop.environments import Environment, free_space
from teleop_core.loop.kernel import kernel_for
from teleop_core.loop.layout import SAMPLE_COLUMNS
from teleop_core.loop.link import (
    NO_LINKS,
    NO_PACKETS,
    POOL_NEXT,
    Link,
    kernel_links,
    packet_schedule,
)
from teleop_core.master.dial import D_OMEGA, D_THETA, DIAL_STATE_SIZE, dial_param_vector
from teleop_core.master.haptics import LOADING, rate_command

if TYPE_CHECKING:
    from teleop_core.loop.follower_units import PhysicalFollower
    from teleop_core.loop.hardware import HardwareDriver

__all__ = ["TeleopLoop"]


def _hand_to_loop(action: HandAction, loop: np.ndarray) -> None:
    """Write what the hand does until the driver's next update into the loop's slots."""
    loop[K.L_ROT_ACTION] = action.rotation_rate_rad_s
    loop[K.L_HAND_TARGET] = action.dial_target_rad
    loop[K.L_HAND_K] = action.grip_stiffness_n_m_per_rad
    loop[K.L_HAND_B] = action.grip_damping_n_m_s_per_rad
    loop[K.L_HAND_PUSH] = action.push_n_m


class TeleopLoop:
    """One trial's closed loop. `run(seconds, driver)` or step it with `advance`.

    Parameters
    ----------
    config : LoopConfig
    environment : Environment
        What the guidewire meets (default: free space).
    estimator : ForceEstimator or None
        The follower's force estimator; None publishes the true proximal force.
    seed : int
        Seeds sensor noise and the link's jitter and losses.
    force_override : callable or None
        t_s -> N replacing the published force (the latency bench's step).
    """

    def __init__(
        self,
        config: LoopConfig | None = None,
        environment: Environment | None = None,
        estimator: ForceEstimator | None = None,
        seed: int = 0,
        force_override: Callable[[float], float] | None = None,
        keep_ticks: bool = False,
        fast: bool = True,
    ) -> None:
        self.config = cfg = config or LoopConfig()
        self.environment = environment or free_space()
        self.environment.reset()
        self._kernel = kernel_for(self.environment.fn)
        self.estimator = estimator
        self.force_override = force_override
        self.keep_ticks = keep_ticks
        self.rng = np.random.default_rng(seed)
        self.dt_s = 1.0 / cfg.device_rate_hz
        self._acq_every = round(cfg.device_rate_hz / cfg.acquisition_rate_hz)
        self._est_every = round(cfg.device_rate_hz / cfg.estimation_rate_hz)
        self._drv_every = round(cfg.device_rate_hz / cfg.driver_rate_hz)  # see start()
        link_rng = np.random.default_rng(self.rng.integers(2**63))
        self._link_rng = link_rng
        self.to_follower: Link[tuple[float, float]] = Link(cfg.to_follower, link_rng)
        self.to_master: Link[float] = Link(cfg.to_master, link_rng)
        self.loop = np.zeros(K.LOOP_STATE_SIZE)
        self.loop[K.L_BRANCH] = LOADING
        self.mp = master_vector(cfg, estimator)
        self.dial = np.zeros(DIAL_STATE_SIZE)
        self.dp = dial_param_vector(cfg.dial)
        self.follower = np.zeros(STATE_SIZE)
        self.fp = _param_vector(cfg.plant, cfg.control)
        self.f_enc_step = 2 * math.pi / cfg.sensors.encoder_counts_per_rev
        self._wheel_radius_m = cfg.plant.wheel_radius_m
        self._branches = self.environment.branches
        self.counters = LoopCounters()
        self._stream = estimator.stream() if estimator is not None else None
        self._log = np.zeros((max(self._acq_every, self._drv_every, self._est_every), K.LOG_WIDTH))
        self._last_row = [0.0] * K.LOG_WIDTH
        self._schedule = np.zeros((8, K.SCHEDULE_WIDTH))
        self._noise = np.zeros(0)
        self._fast_allowed = fast
        self._fast = False
        self._est_arrays = (
            self._stream.kernel_arrays() if self._stream is not None else NO_STREAM_ARRAYS
        )
        self._samples = np.zeros((0, len(SAMPLE_COLUMNS)))
        self._action = HandAction()
        self._done_s = math.nan
        self._success = False
        self.driver: Driver | None = None
        self.physical_follower: PhysicalFollower | None = None
        """The real drive and force sensors (the driver's `follower`), once started."""
        self._links: tuple[Any, ...] = NO_LINKS
        """The in-kernel links (`link.kernel_links`) of the fast path, once started."""
        self._pool = np.zeros(0)
        self._pool_pos = np.zeros(1)

    def _started_driver(self) -> Driver:
        """The driver of `start`, which the loop needs from its first step on."""
        if self.driver is None:
            raise RuntimeError("the loop is advanced before start(driver)")
        return self.driver

    def _reserve_draws(self, count: int) -> None:
        pos = int(self._pool_pos[POOL_NEXT])
        if len(self._pool) - pos < count:
            fresh = self._link_rng.random(max(4096, count))
            self._pool = np.concatenate([self._pool[pos:], fresh])
            self._pool_pos[POOL_NEXT] = 0.0
            links = list(self._links)
            links[K.LK_POOL] = self._pool
            self._links = tuple(links)

    @property
    def t_s(self) -> float:
        return self.counters.ticks * self.dt_s

    def view(self) -> OperatorView:
        row = self._last_row
        branch = self.environment.branches[int(row[K.LOG_BRANCH])]
        return OperatorView(
            t_s=self.t_s,
            dial_angle_rad=float(self.dial[D_THETA]),
            dial_speed_rad_s=float(self.dial[D_OMEGA]),
            insertion_m=float(self.follower[THETA] * self.config.plant.wheel_radius_m),
            rotation_rad=float(self.loop[K.L_ROTATION]),
            tip_m=(float(row[K.LOG_TIP_X]), float(row[K.LOG_TIP_Y]), float(row[K.LOG_TIP_Z])),
            branch=branch,
            success=bool(row[K.LOG_SUCCESS]),
        )

    def _row_view(self) -> OperatorView:
        """`view` from the last tick's log row alone (the fast path: no real dial writes
        the dial's state between the kernel's calls). The row holds the dial's,
        follower's and platform's state as the tick left them, so the view is the
        same, with no reads of the state arrays. Its fields are written into the
        instance's dict at once (one view per driver update; the frozen dataclass's own
        __init__ sets each through object.__setattr__)."""
        row = self._last_row
        view = object.__new__(OperatorView)
        view.__dict__.update(
            t_s=self.counters.ticks * self.dt_s,
            dial_angle_rad=row[K.LOG_DIAL_ANGLE],
            dial_speed_rad_s=row[K.LOG_DIAL_SPEED],
            insertion_m=row[K.LOG_WHEEL_ANGLE] * self._wheel_radius_m,
            rotation_rad=row[K.LOG_ROTATION],
            tip_m=(row[K.LOG_TIP_X], row[K.LOG_TIP_Y], row[K.LOG_TIP_Z]),
            branch=self._branches[int(row[K.LOG_BRANCH])],
            success=row[K.LOG_SUCCESS] != 0.0,
        )
        return view

    def run(self, seconds: float, driver: Driver, stop_when_done: bool = True) -> LoopResult:
        """Run up to `seconds` (or until the driver says done); return every sample."""
        self.start(driver)
        chunks, ticks = [], []
        n_total = round(seconds / self.dt_s)
        while self.counters.ticks < n_total:
            samples, tick_log = self._advance_to(n_total)
            chunks.append(samples)
            if tick_log is not None:
                ticks.append(tick_log)
            if stop_when_done and not math.isnan(self._done_s):
                break
        return self._result(chunks, ticks)

    def start(self, driver: Driver) -> None:
        if self.driver is not None:
            raise TeleopInputError("this loop has already started; build a new one per trial")
        self.driver = driver
        if driver.rate_hz is not None:
            ratio = self.config.device_rate_hz / driver.rate_hz
            if not (ratio >= 1 and abs(ratio - round(ratio)) < 1e-9):
                raise TeleopInputError(
                    f"driver rate {driver.rate_hz} Hz does not divide the device rate "
                    f"{self.config.device_rate_hz} Hz"
                )
            self._drv_every = round(ratio)
        driver.start(np.random.default_rng(self.rng.integers(2**63)))
        self.physical_follower = getattr(driver, "follower", None)
        self.mp[K.M_DIAL_EXTERNAL] = 1.0 if driver.physical_dial else 0.0
        # acquisitions, estimates and the link run inside the kernel between driver
        # events unless something outside it must see each packet
        self._fast = (
            self._fast_allowed
            and self.force_override is None
            and not driver.physical_dial
            and not driver.realtime
            and self.physical_follower is None
        )
        if self._fast:
            self._links = kernel_links(self.to_master.params, self.to_follower.params)
            self._pool, self._pool_pos = self._links[K.LK_POOL], self._links[K.LK_POS]
        self.mp[K.M_FAST] = 1.0 if self._fast else 0.0
        self._wall_start = time.monotonic() - self.t_s

    def advance(self, seconds: float) -> np.ndarray:
        """Advance by `seconds` (whole ticks); return the samples acquired meanwhile."""
        if self.driver is None:
            raise TeleopInputError("call start(driver) before advance()")
        samples, _ = self._advance_to(self.counters.ticks + round(seconds / self.dt_s))
        return samples

    @property
    def done(self) -> bool:
        return not math.isnan(self._done_s)

    @property
    def success(self) -> bool:
        return self._success

    @property
    def done_s(self) -> float:
        """The loop time the driver ended the trial at; NaN while it runs."""
        return self._done_s

    def _result(self, chunks: list[np.ndarray], ticks: list[np.ndarray]) -> LoopResult:
        return LoopResult(
            samples=np.concatenate(chunks) if chunks else np.zeros((0, len(SAMPLE_COLUMNS))),
            counters=self.counters,
            branches=self.environment.branches,
            ticks=np.concatenate(ticks) if ticks else None,
            success=self._success,
            done_s=self._done_s,
        )

    def _advance_to(self, end_tick: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Run events and kernel calls until `end_tick` or the driver is done."""
        if self._fast and not self.keep_ticks:
            return self._advance_fast(end_tick), None
        return self._advance_events(end_tick)

    def _advance_events(self, end_tick: int) -> tuple[np.ndarray, np.ndarray | None]:
        """`_advance_to` event by event, or on the fast path keeping every tick's row."""
        rows: list[tuple[float, ...]] = []  # the event-by-event path's samples
        blocks: list[np.ndarray] = []  # the kernel's samples, a block per call
        # on the fast path the kernel writes its samples straight after the previous
        # call's, into one array for the whole advance (no copy and no block per call)
        out, filled = self._samples, 0
        logs: list[np.ndarray] = []
        env = self.environment
        c = self.counters
        kernel, acq, drv = self._kernel, self._acq_every, self._drv_every
        state = (self.loop, self.mp, self.dial, self.dp, self.follower, self.fp, self.f_enc_step)
        loop = self.loop
        while c.ticks < end_tick and math.isnan(self._done_s):
            k = c.ticks
            # next event tick: a driver update, and (unless the kernel does them) an
            # acquisition
            nxt = min((k // drv + 1) * drv, end_tick)
            if not self._fast:
                nxt = min(nxt, (k // acq + 1) * acq)
            n = nxt - k
            if n > len(self._log):
                self._log = np.zeros((n, K.LOG_WIDTH))
            links = NO_LINKS
            if self._fast:
                self._reserve_noise(n // acq + 2)
                self._reserve_draws(4 * (n // acq + 2))
                if len(out) - filled < n // acq + 2:
                    grown = np.empty((filled + (end_tick - k) // acq + 2, len(SAMPLE_COLUMNS)))
                    grown[:filled] = out[:filled]
                    out = grown
                # the command at a driver tick that ends this call waits for the driver
                self.mp[K.M_DEFER_LAST] = 1.0 if nxt % drv == 0 and nxt % acq == 0 else 0.0
                links = self._links
            log = self._log
            loop[K.L_N_ACQ] = loop[K.L_N_EST] = loop[K.L_N_CMD] = 0.0
            # on the fast path every packet crosses the kernel's own link
            packets = NO_PACKETS if self._fast else self._packets(k, nxt)
            m = kernel(
                n,
                *state,
                env.state,
                env.params,
                log,
                packets,
                self._est_arrays,
                self._noise,
                out[filled:] if self._fast else self._samples,
                links,
            )
            c.ticks = nxt
            if m:
                if self._fast:
                    filled += m
                else:
                    blocks.append(self._samples[:m].copy())
                n_acq, n_est = int(loop[K.L_N_ACQ]), int(loop[K.L_N_EST])
                c.acquisitions += n_acq
                c.commands_sent += int(loop[K.L_N_CMD])
                c.estimates += n_est
                c.forces_sent += n_est
                if self.physical_follower is None:  # the model's tip reached the target
                    self._success = self._success or loop[K.L_SUCCESS] != 0.0
            self._last_row = log[n - 1].tolist()  # Python floats: cheap to index
            if self.keep_ticks:
                logs.append(log[:n].copy())
            self._on_events(rows)
        if filled:
            blocks.append(out[:filled])
        if rows:
            blocks.append(np.array(rows))
        samples = np.concatenate(blocks) if blocks else np.zeros((0, len(SAMPLE_COLUMNS)))
        return samples, (np.concatenate(logs) if logs else None)

    def _advance_fast(self, end_tick: int) -> np.ndarray:
        """`_advance_to` on the fast path, with its per-call work hoisted out of the
        calls: a kernel call per driver update, and between them only the driver.

        The noise, the link's draws and the sample rows are reserved for the whole
        advance at once (later values continue the same random streams, so when they
        are drawn does not change them); the kernel counts acquisitions, estimates and
        commands across its calls, and itself marks the rate command it defers to after
        the driver acts (`L_SEND_PENDING`); the counters are read once at the end.
        """
        c, loop, mp = self.counters, self.loop, self.mp
        acq, drv = self._acq_every, self._drv_every
        k = c.ticks
        if k >= end_tick or not math.isnan(self._done_s):
            return np.zeros((0, len(SAMPLE_COLUMNS)))
        rows_max = (end_tick - k) // acq + 2
        self._reserve_noise(rows_max)
        self._reserve_draws(4 * rows_max)
        # a fresh array per advance: the samples returned are a view of it
        out = np.empty((rows_max, len(SAMPLE_COLUMNS)))
        if len(self._log) < drv:
            self._log = np.zeros((drv, K.LOG_WIDTH))
        kernel, log, env = self._kernel, self._log, self.environment
        fixed: tuple[Any, ...] = (self.loop, mp, self.dial, self.dp, self.follower, self.fp)
        fixed += (self.f_enc_step, env.state, env.params, log, NO_PACKETS, self._est_arrays)
        fixed += (self._noise,)
        links, act, view = self._links, self._started_driver().act, self._row_view
        loop[K.L_N_ACQ] = loop[K.L_N_EST] = loop[K.L_N_CMD] = 0.0
        defer = -1.0
        filled, updates = 0, 0
        while k < end_tick:
            nxt = min((k // drv + 1) * drv, end_tick)
            n = nxt - k
            # the command at a driver tick that ends this call waits for the driver
            at_driver = nxt % drv == 0
            flag = 1.0 if at_driver and nxt % acq == 0 else 0.0
            if flag != defer:
                mp[K.M_DEFER_LAST] = defer = flag
            filled += kernel(n, *fixed, out[filled:], links)
            k = c.ticks = nxt
            self._last_row = log[n - 1].tolist()  # Python floats: cheap to index
            if at_driver:
                # the driver decides what the hand does until its next update
                updates += 1
                action = act(view())
                self._action = action
                _hand_to_loop(action, loop)
                if action.done:
                    self._done_s = self.t_s
                    break
        n_acq, n_est = int(loop[K.L_N_ACQ]), int(loop[K.L_N_EST])
        c.driver_updates += updates
        c.acquisitions += n_acq
        c.commands_sent += int(loop[K.L_N_CMD])
        c.estimates += n_est
        c.forces_sent += n_est
        self._success = self._success or loop[K.L_SUCCESS] != 0.0
        return out[:filled]

    def _on_events(self, rows: list[tuple[float, ...]]) -> None:
        c = self.counters
        if self._fast:
            # the kernel has acquired this tick; after a driver update the master sends
            # the rate command, carrying the new rotation, into the kernel's link: the
            # kernel, which deferred it (M_DEFER_LAST), sends it first thing in its next
            # call, at this tick's time and with the draws it would have taken here
            if c.ticks % self._drv_every == 0:
                self._drive()
            return
        if c.ticks % self._drv_every == 0:
            self._drive()
        if c.ticks % self._acq_every == 0:
            self._acquire(rows)
            self._send_command()
        # packets that arrive at this very tick (a zero-delay link) act from the next
        # tick on: set them now rather than through the kernel's schedule
        t = self.t_s
        if self.to_master.next_arrival_s() <= t + 1e-12:
            self.loop[K.L_FORCE_RX] = self.to_master.receive(t)
        if self.to_follower.next_arrival_s() <= t + 1e-12:
            command = self.to_follower.receive(t)
            if command is not None:  # a packet arrived: the link holds its value
                self.loop[K.L_SPEED_CMD_RX], self.loop[K.L_ROT_RATE_RX] = command

    def _packets(self, k: int, nxt: int) -> np.ndarray:
        schedule, self._schedule = packet_schedule(
            self.to_master, self.to_follower, k, nxt, self.dt_s, self._schedule
        )
        return schedule

    def _acquire(self, rows: list[tuple[float, ...]]) -> None:
        """The follower's ESP32 samples; the estimator runs on every other sample."""
        if self.physical_follower is not None:
            self._acquire_physical(rows, self.physical_follower)
            return
        c, t, row, loop = self.counters, self.t_s, self._last_row, self.loop
        c.acquisitions += 1
        if c.ticks % self._est_every == 0:
            if self._stream is not None:
                self._stream.push(
                    t, row[K.LOG_IQ_FILT] + self._current_noise(), row[K.LOG_OMEGA_EST]
                )
                estimate = self._stream.estimate()
                loop[K.L_FORCE_EST] = estimate[EST_FINAL] if estimate is not None else 0.0
            else:
                loop[K.L_FORCE_EST] = row[K.LOG_PROXIMAL]
            if self.force_override is not None:
                loop[K.L_FORCE_EST] = self.force_override(t)
            c.estimates += 1
            c.forces_sent += 1
            self.to_master.send(t, float(loop[K.L_FORCE_EST]))
        elif self._stream is not None:
            self._stream.push(t, row[K.LOG_IQ_FILT] + self._current_noise(), row[K.LOG_OMEGA_EST])
        r = self.config.plant.wheel_radius_m
        sample = [0.0] * K.SAMPLE_WIDTH
        sample[K.S_T] = t
        sample[K.S_INSERTION] = row[K.LOG_WHEEL_ANGLE] * r
        sample[K.S_ROTATION] = row[K.LOG_ROTATION]
        sample[K.S_TIP_X] = row[K.LOG_TIP_X]
        sample[K.S_TIP_Y] = row[K.LOG_TIP_Y]
        sample[K.S_TIP_Z] = row[K.LOG_TIP_Z]
        sample[K.S_BRANCH] = row[K.LOG_BRANCH]
        sample[K.S_PROXIMAL] = row[K.LOG_PROXIMAL]
        sample[K.S_PROXIMAL_EST] = float(loop[K.L_FORCE_EST])
        sample[K.S_DISTAL] = row[K.LOG_DISTAL]
        sample[K.S_DIAL_ANGLE] = row[K.LOG_DIAL_ANGLE]
        sample[K.S_DIAL_TORQUE] = row[K.LOG_DIAL_TORQUE]
        rows.append(tuple(sample))
        if row[K.LOG_SUCCESS] and not self._success:
            self._success = True

    def _acquire_physical(self, rows: list[tuple[float, ...]], follower: PhysicalFollower) -> None:
        """The real follower's acquisition: the drive gets the speed command the
        follower received over the link; its measured current and speed feed the
        estimator; the sensors' forces are stored. The tip's pose is unknown (no tracker
        on a physical phantom: NaN); the region column is the loop's model's."""
        c, t, row, loop = self.counters, self.t_s, self._last_row, self.loop
        c.acquisitions += 1
        reading = follower.exchange(t, float(loop[K.L_SPEED_CMD_RX]))
        _, iq_a, speed_rad_s = follower.inputs[-1]
        if self._stream is not None:
            self._stream.push(t, iq_a, speed_rad_s)
        if c.ticks % self._est_every == 0:
            if self._stream is not None:
                estimate = self._stream.estimate()
                loop[K.L_FORCE_EST] = estimate[EST_FINAL] if estimate is not None else 0.0
            else:  # no estimator: the reference sensor's force is rendered
                loop[K.L_FORCE_EST] = reading.forces.proximal_n
            c.estimates += 1
            c.forces_sent += 1
            self.to_master.send(t, float(loop[K.L_FORCE_EST]))
        sample = [0.0] * K.SAMPLE_WIDTH
        sample[K.S_T] = t
        sample[K.S_INSERTION] = reading.drive.angle_rad * self.config.plant.wheel_radius_m
        sample[K.S_ROTATION] = row[K.LOG_ROTATION]
        sample[K.S_TIP_X] = sample[K.S_TIP_Y] = sample[K.S_TIP_Z] = math.nan
        sample[K.S_BRANCH] = row[K.LOG_BRANCH]
        sample[K.S_PROXIMAL] = reading.forces.proximal_n
        sample[K.S_PROXIMAL_EST] = float(loop[K.L_FORCE_EST])
        sample[K.S_DISTAL] = reading.forces.distal_n
        sample[K.S_DIAL_ANGLE] = row[K.LOG_DIAL_ANGLE]
        sample[K.S_DIAL_TORQUE] = row[K.LOG_DIAL_TORQUE]
        rows.append(tuple(sample))

    def _current_noise(self) -> float:
        """INA240 noise on the acquired current, A, drawn in blocks (one call per sample
        would cost more than the sample's whole share of the loop); the kernel reads the
        same array at the same position."""
        self._reserve_noise(1)
        pos = int(self.loop[K.L_NOISE_POS])
        self.loop[K.L_NOISE_POS] = pos + 1
        return float(self._noise[pos])

    def _reserve_noise(self, count: int) -> None:
        """At least `count` unused noise values from the current position on; new values
        continue the same random stream, so when they are drawn does not matter."""
        pos = int(self.loop[K.L_NOISE_POS])
        if len(self._noise) - pos < count:
            fresh = self.rng.normal(0.0, self.config.sensors.current_noise_a, max(4096, count))
            self._noise = np.concatenate([self._noise[pos:], fresh])
            self.loop[K.L_NOISE_POS] = 0.0

    def _send_command(self) -> None:
        """The master samples the dial and sends the rate command (eq. 5) to the follower."""
        # v_gw = k_v theta_m (eq. 5), on the dial's encoder angle; omega = v / r at the wheel
        v_gw = rate_command(self.loop[K.L_THETA_Q_PREV], self.config.haptics.speed_gain_m_s_per_rad)
        omega_cmd = v_gw / self.config.plant.wheel_radius_m
        self.counters.commands_sent += 1
        self.to_follower.send(self.t_s, (omega_cmd, self._action.rotation_rate_rad_s))

    def _drive(self) -> None:
        """The driver decides what the hand does until its next update."""
        c = self.counters
        c.driver_updates += 1
        driver = self._started_driver()
        if driver.realtime:
            # keep pace with the wall clock: the person at the hardware lives in it
            lag = self._wall_start + self.t_s - time.monotonic()
            if lag > 0:
                time.sleep(lag)
        if driver.physical_dial:
            # the real dial: send Psi's current, read the angle the person set
            dial = cast("HardwareDriver", driver)  # the one driver with physical_dial
            state = dial.exchange(self.loop[K.L_I_CMD_MA] / 1000.0)  # mA -> A
            self.dial[D_THETA], self.dial[D_OMEGA] = state.angle_rad, state.speed_rad_s
        action = driver.act(self.view())
        self._action = action
        _hand_to_loop(action, self.loop)
        if action.done:
            self._done_s = self.t_s
