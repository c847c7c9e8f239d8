"""Simulated participants for the LCCA task, drawn per experience group.

A simulated participant is a `teleop_core` driver: it sees what a participant sees and
acts through the dial and the rotation joystick. What it sees (`OperatorView`): the
tip on the screen (its position, the vessel it is in, the angled tip's orientation),
the roadmap (where the LCCA's ostium is and which way it faces), and the dial under
its hand. It never reads the condition label or the true force. In HV the force shows
only as torque on the hand: the dial lags the hand's aim by more than the return spring
explains, and the participant eases off or backs out when that surplus torque passes
its threshold. In VO it notices an obstacle only on the screen, when the tip has not
moved for a while. With a haptic gain of 0, HV is therefore VO, draw for draw.

Behaviour: advance at the preferred speed to the LCCA's ostium; slow down over an
approach zone (longer for cautious participants) while turning the tip towards the
ostium with a steering error drawn per attempt; advance past the ostium; if the screen
shows the tip in the LCCA, go on to the target depth (success ends the trial);
otherwise pull back behind the ostium and try again, a little better each time.
After an obstacle (felt or seen) it backs off and tries again. It gives up at
`give_up_s`.

Group distributions (mean, sd; truncated to plausible ranges) are assumptions shaped
by [endovascular], IV-D (experts faster and steadier; the paper reports comparable times and
lower peak forces with haptics in every group), not measured values. The traits and
their group distributions are the study's (`study.protocol.traits`, shared by every
task's simulated participant); a model fitted to a study's trials (`study participants
fit`, `study.protocol.participant_model`) replaces them wherever `--participants
MODEL.json` is given.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from study.protocol.traits import ParticipantTraits, trial_state
from teleop_core.loop.drivers import (
    GRIP_DAMPING_N_M_S_PER_RAD,
    GRIP_STIFFNESS_N_M_PER_RAD,
    Driver,
    HandAction,
    OperatorView,
)
from teleop_core.master.params import HapticParams
from teleop_core.phantom.lcca import LccaPhantom

AORTA = ("descending aorta", "aortic arch", "ascending aorta")


class SimulatedParticipant(Driver):
    """A participant with `traits` navigating `phantom` to its target branch."""

    rate_hz = 25.0
    """Decisions at 25 Hz, the frame rate of the fluoroscopy screen it watches (clinical
    fluoroscopy runs at 7.5-30 frames/s), far faster than any reaction; the hand's
    impedance still acts at the 1 kHz device rate."""

    def __init__(
        self,
        traits: ParticipantTraits,
        phantom: LccaPhantom,
        give_up_s: float = 180.0,
        spring_n_m_per_rad: float = HapticParams().spring_n_m_per_rad,
        speed_gain_m_s_per_rad: float = HapticParams().speed_gain_m_s_per_rad,
    ) -> None:
        self.person = traits
        """The person's own traits; `traits` is their state in the current trial."""
        self.traits = traits
        self.give_up_s = give_up_s
        self.target = phantom.anatomy.target
        branch = next(b for b in phantom.anatomy.branches if b.name == self.target)
        self.target_phi = branch.phi_rad
        self.ostium_m = phantom.ostium_m(self.target)
        self.target_depth_m = phantom.anatomy.target_depth_m
        # the roadmap: the aortic centreline the tip is located on, and the ostium
        self.roadmap = phantom.centreline(0)
        self.ostium_xyz = tuple(self.roadmap[round(self.ostium_m / 0.001)])
        self._road = [tuple(point) for point in self.roadmap]
        self._road_index = 0
        # what practice taught: the dial's spring and speed gain (eqs. 5, 8)
        self.spring_guess = spring_n_m_per_rad
        self.speed_gain_guess = speed_gain_m_s_per_rad

    def start(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.traits = trial_state(self.person, rng)
        self._road_index = 0
        self.phase = "advance"
        self.attempt = 0
        self.aim_error = 0.0
        self.back_off_to = 0.0
        self._seen: deque[OperatorView] = deque()
        self._stall_ref = (0.0, 0.0, 0.0)
        self._stall_clock = 0.0
        self._felt_since = math.nan
        self.obstacles_felt = 0
        self.obstacles_seen = 0
        self._last_aim = 0.0
        self._felt = 0.0
        self._baseline = math.nan
        self._new_attempt()

    def _new_attempt(self) -> None:
        # steering improves with each try
        sd = self.traits.steering_error_rad * (0.7**self.attempt)
        self.aim_error = float(self.rng.normal(0.0, sd))
        self.attempt += 1

    def _arc_length(self, tip: tuple[float, float, float]) -> float:
        """Where the tip is along the roadmap (nearest centreline point, m): a local
        search from the last answer, as the tip moves well under a millimetre per look."""
        road, k = self._road, self._road_index
        best = math.dist(road[k], tip)
        for step in (1, -1):
            j = k + step
            while 0 <= j < len(road):
                d = math.dist(road[j], tip)
                if d >= best:
                    break
                best, k = d, j
                j += step
        if best > 0.01:  # lost the thread (a jump): search the whole roadmap
            k = min(range(len(road)), key=lambda i: math.dist(road[i], tip))
        self._road_index = k
        return k * 0.001

    def act(self, view: OperatorView) -> HandAction:
        tr = self.traits
        self._seen.append(view)
        while len(self._seen) > 1 and self._seen[1].t_s <= view.t_s - tr.reaction_s:
            self._seen.popleft()
        seen = self._seen[0]  # the screen, reaction_s ago
        if seen.success or view.t_s >= self.give_up_s:
            return HandAction(done=True)
        in_target = seen.branch == self.target
        if in_target:
            s_tip = self.ostium_m + math.dist(seen.tip_m, self.ostium_xyz)
        else:
            s_tip = self._arc_length(seen.tip_m)
        dt = 1.0 / self.rate_hz
        felt_for = self._feel(view, dt)
        stalled = self._stalled(seen, dt)
        if self.phase in ("advance", "enter", "navigate") and (
            stalled or felt_for > tr.reaction_s * 0.6
        ):
            self._back_off(stalled, s_tip, in_target)
        speed, rotation = self._plan(view, seen, s_tip, in_target)
        # asked to keep forces low, a participant who feels the resistance pushes more
        # gently the more it exceeds what it finds comfortable (HV only: without
        # haptics there is nothing to feel)
        excess = min(max(self._felt - tr.comfort_torque_n_m, 0.0) / tr.comfort_torque_n_m, 3.0)
        if speed > 0:
            speed /= 1.0 + tr.caution * excess
        aim = speed / self.speed_gain_guess
        self._last_aim = aim
        return HandAction(
            dial_target_rad=aim,
            grip_stiffness_n_m_per_rad=GRIP_STIFFNESS_N_M_PER_RAD,
            grip_damping_n_m_s_per_rad=GRIP_DAMPING_N_M_S_PER_RAD,
            rotation_rate_rad_s=rotation,
        )

    def _feel(self, view: OperatorView, dt: float) -> float:
        """How long (s) the hand has felt a rise of resistance above its threshold, 0 if
        it feels none now."""
        tr = self.traits
        # felt torque: what the hand holds beyond what the spring alone explains
        # (positive when the dial resists the forward push), smoothed over 0.1 s as a
        # hand feels it; without haptics it stays near zero
        hand = GRIP_STIFFNESS_N_M_PER_RAD * (self._last_aim - view.dial_angle_rad)
        surplus = hand - self.spring_guess * view.dial_angle_rad
        self._felt += (surplus - self._felt) * dt / 0.1
        pushing = self._last_aim > 0.02
        rise = 0.0
        if pushing:
            # people sense a change of resistance against what they felt just before
            if math.isnan(self._baseline):
                self._baseline = self._felt
            rise = self._felt - self._baseline
            self._baseline += (self._felt - self._baseline) * dt / 3.0
        else:
            self._baseline = math.nan
        felt = pushing and rise > tr.haptic_threshold_n_m
        self.last_surplus, self.last_rise = self._felt, rise
        if felt and math.isnan(self._felt_since):
            self._felt_since = view.t_s
        elif not felt:
            self._felt_since = math.nan
        return 0.0 if math.isnan(self._felt_since) else view.t_s - self._felt_since

    def _stalled(self, seen: OperatorView, dt: float) -> bool:
        """Whether the hand has pushed for `visual_stall_s` in all since the tip on the
        screen last moved a millimetre (a seen obstacle)."""
        if math.dist(seen.tip_m, self._stall_ref) >= 0.001:
            self._stall_ref = seen.tip_m
            self._stall_clock = 0.0
        elif self._last_aim > 0.02 and self.phase in ("advance", "enter", "navigate"):
            self._stall_clock += dt
        # a slow push needs longer to show a millimetre
        expected_speed = max(self.speed_gain_guess * self._last_aim, 0.001)
        return self._stall_clock >= self.traits.visual_stall_s + min(0.001 / expected_speed, 1.0)

    def _back_off(self, stalled: bool, s_tip: float, in_target: bool) -> None:
        """An obstacle seen (`stalled`) or felt: count it and back off."""
        if stalled:
            self.obstacles_seen += 1
        else:
            self.obstacles_felt += 1
        self.phase = "back_off"
        # behind the ostium if the tip stuck at it, else a centimetre back
        near_ostium = abs(s_tip - self.ostium_m) < 0.01 and not in_target
        self.back_off_to = self.ostium_m - 0.01 if near_ostium else max(s_tip - 0.01, 0.005)
        self._stall_clock = 0.0
        self._felt_since = math.nan

    def _plan(
        self, view: OperatorView, seen: OperatorView, s_tip: float, in_target: bool
    ) -> tuple[float, float]:
        """(speed, rotation rate) for the current phase."""
        tr = self.traits
        v = tr.preferred_speed_m_s
        approach = 0.02 + 0.03 * tr.caution
        phi_aim = self.target_phi + self.aim_error
        rot_err = math.remainder(phi_aim - seen.rotation_rad, 2 * math.pi)
        # turn towards the aim; a gain matched to the reaction delay keeps the delayed
        # correction from overshooting into oscillation
        rotation = min(max(0.8 / tr.reaction_s * rot_err, -2.0), 2.0)
        if self.phase == "back_off":
            if s_tip <= self.back_off_to or (in_target and s_tip <= self.back_off_to + 0.01):
                self.phase = "navigate" if in_target else "advance"
                if not in_target:
                    self._new_attempt()
            return -v, rotation
        if seen.branch not in AORTA and not in_target:
            # the screen shows the tip in another branch: pull back into the arch
            self.phase = "retract"
            return -v, rotation
        if self.phase == "retract":
            if s_tip < self.ostium_m - 0.01 and not in_target:
                self.phase = "advance"
                self._new_attempt()
            return -v, rotation
        if in_target:
            self.phase = "navigate"
            return v * (0.6 + 0.4 * (1 - tr.caution)), 0.0
        if s_tip < self.ostium_m - approach:
            self.phase = "advance"
            return v, rotation
        if s_tip < self.ostium_m + 0.006:
            self.phase = "enter"
            # wait for the tip to point the right way before pushing through the ostium
            slow = max(v * (1.0 - 0.6 * tr.caution), 0.004)
            return (slow if abs(rot_err) < 0.15 else 0.0), rotation
        # past the ostium and not in the target: wrong way, pull back and retry
        self.phase = "retract"
        return -v, rotation
