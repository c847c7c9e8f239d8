"""The closed loop: rate bookkeeping, link delays, VO/HV, the estimator in the loop."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import replace

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.loop.config import LoopConfig
from teleop_core.loop.core import TeleopLoop
from teleop_core.loop.drivers import (
    Driver,
    HandAction,
    KeyboardDriver,
    OperatorView,
    SimulatedOperator,
)
from teleop_core.loop.environments import free_space, tube_with_wall
from teleop_core.loop.layout import SAMPLE_COLUMNS
from teleop_core.loop.link import LinkParams
from teleop_core.master.params import HapticParams
from tests.teleop_core.test_gru import GRU_F32_TOLERANCE


class Hold(Driver):
    """Holds the dial at a fixed aim with a firm grip; records every view."""

    def __init__(self, aim_rad: float = 0.0, from_s: float = 0.0) -> None:
        self.aim_rad, self.from_s, self.views = aim_rad, from_s, []

    def act(self, view: OperatorView) -> HandAction:
        self.views.append(view)
        aim = self.aim_rad if view.t_s >= self.from_s else 0.0
        return HandAction(aim, 2.0, 0.03)


def test_each_part_runs_at_its_own_rate() -> None:
    loop = TeleopLoop(seed=1)
    result = loop.run(1.0, Hold())
    c = result.counters
    assert (c.ticks, c.acquisitions, c.estimates, c.driver_updates) == (1000, 100, 50, 100)
    assert c.forces_sent == 50
    assert c.commands_sent == 100
    frame = result.to_frame()
    assert list(frame.columns) == list(SAMPLE_COLUMNS)
    assert np.allclose(frame["t_s"], np.arange(1, 101) * 0.01)


def test_stepping_in_pieces_equals_one_run() -> None:
    whole = TeleopLoop(environment=tube_with_wall(), seed=3).run(2.0, SimulatedOperator())
    loop = TeleopLoop(environment=tube_with_wall(), seed=3)
    loop.start(SimulatedOperator())
    pieces = np.concatenate([loop.advance(0.25) for _ in range(8)])
    assert np.array_equal(pieces, whole.samples)


def test_clockwise_dial_advances_the_guidewire_at_k_v_theta() -> None:
    loop = TeleopLoop(seed=2)
    frame = loop.run(2.0, Hold(aim_rad=0.4)).to_frame()
    late = frame[frame["t_s"] > 1.0]
    speed = np.polyfit(late["t_s"], late["insertion_m"], 1)[0]
    # v = k_v theta (eq. 5), theta close to the aim under a firm grip
    theta = late["dial_angle_rad"].mean()
    assert theta > 0.35
    assert speed == pytest.approx(HapticParams().speed_gain_m_s_per_rad * theta, rel=0.03)


@pytest.mark.parametrize("delay_ms", [0.0, 7.0, 20.0])
def test_the_force_reaches_the_master_after_the_link_delay(delay_ms: float) -> None:
    cfg = LoopConfig(to_master=LinkParams(delay_s=delay_ms / 1000))
    loop = TeleopLoop(cfg, force_override=lambda t: 1.0 if t >= 0.3 else 0.0, keep_ticks=True)
    ticks = loop.run(0.5, Hold()).ticks_frame()
    first = ticks["t_s"][ticks["force_rx_n"] == 1.0].iloc[0]
    # published at the first 50 Hz estimate at or after 0.3 s; acts from the next tick
    assert first == pytest.approx(0.3 + delay_ms / 1000 + 0.001, abs=1e-9)


def test_the_rate_command_reaches_the_follower_after_the_link_delay() -> None:
    delay = 0.015
    cfg = LoopConfig(to_follower=LinkParams(delay_s=delay))
    sent = TeleopLoop(keep_ticks=True).run(1.0, Hold(0.4, from_s=0.5)).ticks_frame()
    late = TeleopLoop(cfg, keep_ticks=True).run(1.0, Hold(0.4, from_s=0.5)).ticks_frame()
    t_sent = sent["t_s"][sent["speed_cmd_rx_rad_s"] > 0].iloc[0]
    t_late = late["t_s"][late["speed_cmd_rx_rad_s"] > 0].iloc[0]
    assert t_late - t_sent == pytest.approx(delay, abs=1e-9)


def test_losing_every_packet_holds_the_last_command() -> None:
    cfg = LoopConfig(to_follower=LinkParams(loss=1.0))
    frame = TeleopLoop(cfg).run(1.0, Hold(0.4)).to_frame()
    assert np.all(frame["insertion_m"] == 0.0)


def test_released_dial_returns_to_centre_on_its_spring() -> None:
    class Release(Driver):
        def act(self, view: OperatorView) -> HandAction:
            return HandAction(0.6, 2.0, 0.03) if view.t_s < 0.5 else HandAction()

    frame = TeleopLoop(seed=4).run(2.0, Release()).to_frame()
    assert frame["dial_angle_rad"][frame["t_s"] < 0.5].iloc[-1] > 0.5
    # eq. 8 pulls it back until static friction holds it: |theta| <= ts / K_s
    from teleop_core.master.params import DialParams

    band = DialParams().static_friction_n_m / HapticParams().spring_n_m_per_rad
    assert abs(frame["dial_angle_rad"].iloc[-1]) <= band + 2e-3


def _trial(haptics: HapticParams) -> np.ndarray:
    cfg = LoopConfig(haptics=haptics)
    env = tube_with_wall(friction_n_per_m=8.0)
    return TeleopLoop(cfg, env, seed=5).run(8.0, SimulatedOperator()).samples


def test_hv_with_zero_gain_is_vo_and_hv_slows_the_hand() -> None:
    vo = _trial(HapticParams(haptics_on=False))
    hv0 = _trial(HapticParams(haptics_on=True, haptic_gain_n_m_per_n=0.0))
    hv = _trial(HapticParams(haptics_on=True))
    assert np.array_equal(vo, hv0)
    col = SAMPLE_COLUMNS.index
    # the felt torque deflects the grip: smaller dial angle, shorter insertion
    assert hv[-1, col("insertion_m")] < vo[-1, col("insertion_m")]
    assert np.all(hv[:, col("dial_torque_n_m")] <= vo[:, col("dial_torque_n_m")] + 1e-3)


def test_the_estimator_in_the_loop_tracks_the_proximal_force(small_estimator) -> None:
    env = tube_with_wall(friction_n_per_m=5.0)
    frame = (
        TeleopLoop(environment=env, estimator=small_estimator, seed=6)
        .run(10.0, SimulatedOperator(target_depth_m=0.3))
        .to_frame()
    )
    moving = frame[frame["t_s"] > 1.0]
    error = moving["proximal_force_n"] - moving["reference_force_n"]
    assert moving["reference_force_n"].max() > 0.5
    assert math.sqrt(np.mean(error**2)) < 0.2


def test_keyboard_driver_turns_and_releases_the_dial() -> None:
    now = [0.0]
    kb = KeyboardDriver(step_rad=0.1, clock=lambda: now[0])
    view = TeleopLoop().view()
    for _ in range(3):
        kb.press("advance")
    kb.press("rotate_cw")
    action = kb.act(view)
    assert action.dial_target_rad == pytest.approx(0.3)
    assert action.grip_stiffness_n_m_per_rad > 0
    assert action.rotation_rate_rad_s > 0
    now[0] = 1.0  # the joystick key was not repeated: it springs back
    assert kb.act(view).rotation_rate_rad_s == 0.0
    kb.press("release")
    assert kb.act(view).grip_stiffness_n_m_per_rad == 0.0
    with pytest.raises(TeleopInputError, match="unknown key"):
        kb.press("jump")


def test_keyboard_in_the_loop_advances_the_guidewire() -> None:
    kb = KeyboardDriver()
    loop = TeleopLoop(environment=free_space())
    loop.start(kb)
    for _ in range(4):
        kb.press("advance")
    samples = loop.advance(1.0)
    assert samples[-1, SAMPLE_COLUMNS.index("insertion_m")] > 0.005


def test_rates_that_do_not_divide_the_device_rate_are_refused() -> None:
    with pytest.raises(TeleopInputError, match="does not divide"):
        LoopConfig(acquisition_rate_hz=300.0)
    with pytest.raises(TeleopInputError, match="whole number"):
        replace(LoopConfig(), estimation_rate_hz=40.0)


@pytest.mark.parametrize("damper, settles", [(0.0, False), (None, True)])
def test_the_return_damper_is_what_keeps_a_released_dial_stable(
    damper: float | None, settles: bool
) -> None:
    """Through the current loop's lag, J tau s^3 + J s^2 + B_s s + K_s has a root in the
    right half-plane when B_s = 0 (Routh-Hurwitz: a2 a1 = 0 < a3 a0)."""
    from teleop_core.master.params import DialParams

    dial = DialParams(static_friction_n_m=0.0, coulomb_friction_n_m=0.0)
    haptics = HapticParams() if damper is None else HapticParams(damper_n_m_s_per_rad=damper)
    cfg = LoopConfig(dial=dial, haptics=haptics)

    class Release(Driver):
        def act(self, view: OperatorView) -> HandAction:
            return HandAction(0.3, 2.0, 0.03) if view.t_s < 0.3 else HandAction()

    angle = TeleopLoop(cfg).run(3.0, Release()).to_frame()["dial_angle_rad"].to_numpy()
    late_swing = np.ptp(angle[-50:])
    assert (late_swing < 0.01) == settles


@pytest.mark.parametrize(
    "link",
    [
        LinkParams(),
        LinkParams(delay_s=0.002, jitter_s=0.001, loss=0.01),
        LinkParams(delay_s=0.015, jitter_s=0.02, loss=0.2),
    ],
)
def test_in_kernel_acquisition_matches_the_event_by_event_loop(
    small_estimator,
    link: LinkParams,
) -> None:
    """The kernel runs the acquisitions, the estimator and the link between driver events;
    the samples must be exactly those of the loop that stops at every acquisition and
    sends every packet through `Link` (same draws, same ticks)."""
    runs = []
    for fast in (True, False):
        cfg = LoopConfig(to_follower=link, to_master=link)
        loop = TeleopLoop(cfg, tube_with_wall(), estimator=small_estimator, seed=8, fast=fast)
        runs.append(loop.run(6.0, SimulatedOperator(target_depth_m=0.3)))
        assert loop._fast is fast
    assert np.array_equal(runs[0].samples, runs[1].samples)
    assert runs[0].counters == runs[1].counters


class _LibmStream:
    """The estimator's stream with the GRU in its libm form (`_window_forward_libm`): the
    path the loop ran before the vectorised GRU, rebuilt from the same stages."""

    def __new__(cls, estimator):  # type: ignore[no-untyped-def]
        from teleop_core.estimation.ekf import ekf_update
        from teleop_core.estimation.gru import _window_forward_libm
        from teleop_core.estimation.model import CausalEstimator
        from teleop_core.estimation.stream import S_ALPHA, S_COUNT, S_IQ, S_OMEGA
        from teleop_core.follower.physics import force_at

        class Stream(CausalEstimator):
            def estimate(self):  # type: ignore[no-untyped-def]
                st = self.state
                if st[S_COUNT] < self.buffer.shape[0]:
                    return None
                f_phys = force_at(self.physics, st[S_IQ], st[S_OMEGA], st[S_ALPHA])
                w = self.est.gru.weights
                y = _window_forward_libm(
                    self.buffer, w.w_ih, w.w_hh, w.b_ih, w.b_hh, w.w_out, w.b_out
                )
                f_hybrid = f_phys + y * self.target[0] + self.target[1]
                final = ekf_update(
                    self.ekf_state,
                    self.ekf_settings,
                    self.physics,
                    self.dt_s,
                    f_phys,
                    f_hybrid,
                    st[S_OMEGA],
                )
                return f_phys, f_hybrid, final

        return Stream(estimator)


def _estimate_tolerance_n(estimator) -> float:  # type: ignore[no-untyped-def]
    """The GRU's tolerance against torch's float32 GRU (`test_gru.py`), de-standardised to
    N: how far the float32 kernel's estimate may be from the float64 libm path's."""
    return GRU_F32_TOLERANCE * estimator.gru.standardisation.target_std


def test_float32_gru_keeps_the_vo_samples_of_the_libm_gru(small_estimator, monkeypatch) -> None:
    """The in-kernel GRU runs in float32; against the loop with the float64 libm form (the
    event-by-event loop, whose estimator is swapped), every column but the estimate is
    identical and the estimate within the GRU's float32 tolerance, as long as the
    estimate does not feed back (haptics off, as in the VO condition). With haptic
    feedback the estimate moves the dial (`test_hv_samples_against_the_libm_gru_path`)."""
    cfg = LoopConfig(haptics=HapticParams(haptics_on=False))
    new = TeleopLoop(cfg, tube_with_wall(), estimator=small_estimator, seed=3)
    new_run = new.run(6.0, SimulatedOperator(target_depth_m=0.3))
    monkeypatch.setattr(type(small_estimator), "stream", lambda self: _LibmStream(self))
    old = TeleopLoop(cfg, tube_with_wall(), estimator=small_estimator, seed=3, fast=False)
    old_run = old.run(6.0, SimulatedOperator(target_depth_m=0.3))
    assert new._fast
    assert not old._fast
    est = SAMPLE_COLUMNS.index("proximal_force_n")
    others = [i for i in range(len(SAMPLE_COLUMNS)) if i != est]
    assert np.array_equal(new_run.samples[:, others], old_run.samples[:, others])
    estimate_new, estimate_old = new_run.samples[:, est], old_run.samples[:, est]
    assert np.count_nonzero(estimate_old) > 100  # the GRU ran
    assert np.max(np.abs(estimate_new - estimate_old)) <= _estimate_tolerance_n(small_estimator)


HV_TOLERANCE = 1e-9
"""How far (in each column's unit, the estimate's aside) an HV sample of the loop may be
from the libm-GRU, event-by-event path's in the test below."""

AGREED_SAMPLES_MIN = 100
"""The shortest span (samples at 100 Hz: one second) over which the two paths of the test
below must agree before a discrete decision may part them."""


def test_hv_samples_against_the_libm_gru_path(small_estimator, monkeypatch) -> None:
    """With haptic feedback on (HV) the estimate moves the dial, so the float32 GRU's
    rounding (within GRU_F32_TOLERANCE of torch's float32 GRU, `test_gru.py`) does not
    stay in the estimate column: it enters the dial's state through the haptic torque.
    Against the path the loop ran before the float32 GRU and the in-kernel acquisition
    (the float64 libm GRU, event by event), with haptics on: the same counters and trial
    length, the estimate within the GRU's tolerance (de-standardised) throughout, and
    every other column within HV_TOLERANCE. That holds while the two take the same
    discrete decisions (the dial's 12-bit encoder counts, the haptic deadband's edge):
    from the first they take apart, the trials part, as long LCCA trials do
    (`benchmarks/results/loop_speed.md`), so the comparison runs up to there and that
    span must be at least a second."""
    new = TeleopLoop(LoopConfig(), tube_with_wall(), estimator=small_estimator, seed=4)
    new_run = new.run(6.0, SimulatedOperator(target_depth_m=0.3))
    monkeypatch.setattr(type(small_estimator), "stream", lambda self: _LibmStream(self))
    old = TeleopLoop(LoopConfig(), tube_with_wall(), estimator=small_estimator, seed=4, fast=False)
    old_run = old.run(6.0, SimulatedOperator(target_depth_m=0.3))
    assert new._fast
    assert not old._fast
    assert new_run.counters == old_run.counters
    a, b = new_run.samples, old_run.samples
    assert a.shape == b.shape
    est = SAMPLE_COLUMNS.index("proximal_force_n")
    others = [i for i in range(len(SAMPLE_COLUMNS)) if i != est]
    assert np.count_nonzero(b[:, est]) > 100  # the GRU ran
    assert np.ptp(b[:, SAMPLE_COLUMNS.index("dial_torque_n_m")]) > 0.01  # the dial felt it
    # The two part for good at the first discrete decision they take differently (an
    # encoder count, the haptic deadband's edge), which a float32 rounding of the
    # estimate can tip; where that falls depends on the trained GRU, so on the machine
    # that trained it. Up to there every column agrees, and that span is a second or more.
    apart = np.max(np.abs(a[:, others] - b[:, others]), axis=1) > HV_TOLERANCE
    agreed = int(np.argmax(apart)) if apart.any() else len(a)
    assert agreed >= AGREED_SAMPLES_MIN
    assert np.max(np.abs(a[:agreed, est] - b[:agreed, est])) <= _estimate_tolerance_n(
        small_estimator
    )


def test_the_fast_paths_view_is_the_view_of_the_state() -> None:
    # the fast path builds the driver's view from the last log row, bypassing the
    # dataclass's __init__: it must equal the view read from the state arrays
    loop = TeleopLoop(LoopConfig(), tube_with_wall(), seed=2)
    loop.start(SimulatedOperator(target_depth_m=0.3))
    for _ in range(5):
        loop.advance(0.37)
        fast, slow = loop._row_view(), loop.view()
        assert type(fast) is OperatorView
        assert fast == slow
    assert loop.view().insertion_m > 0.0  # the loop moved


@pytest.mark.parametrize(
    "kwargs",
    [
        {"dial_target_rad": math.nan},
        {"push_n_m": math.inf},
        {"rotation_rate_rad_s": -math.inf},
        {"grip_stiffness_n_m_per_rad": -0.1},
        {"grip_damping_n_m_s_per_rad": -1e-3},
    ],
)
def test_a_hand_action_refuses_bad_values(kwargs: dict[str, float]) -> None:
    with pytest.raises(TeleopInputError, match="hand action"):
        HandAction(**kwargs)


def test_a_hand_action_is_a_frozen_dataclass_with_its_defaults() -> None:
    action = HandAction(0.1, 0.3, rotation_rate_rad_s=0.5)
    assert action == HandAction(0.1, 0.3, 0.0, 0.0, 0.5, False)
    assert action.grip_damping_n_m_s_per_rad == 0.0
    assert not action.done
    assert [f.name for f in dataclasses.fields(HandAction)][-1] == "done"
    with pytest.raises(dataclasses.FrozenInstanceError):
        action.done = True  # type: ignore[misc]
