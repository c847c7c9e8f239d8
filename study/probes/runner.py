"""A participant's probes, run one trial after another with a responder.

A responder gives the answer to one stimulus:
- `SimulatedResponder`: a simulated participant's traits (`Probe.answer`, with the lapse
  rate and response noise its probe module states);
- `KeyboardResponder`: the terminal: the probe's prompt, then a key (or a typed value);
  the time from the prompt to the key is the response time;
- `DeviceResponder`: the dial unit through the hardware driver's interface
  (`teleop_core.loop.hardware.HardwareDriver.exchange`): state lines are read at 100 Hz
  until the hand confirms (the dial pushed past `CONFIRM_RAD`) or the trial times out;
  the rows are `base.DEVICE_COLUMNS` and the probe reads its answer off them.

Forced-choice probes get the interval holding the stimulus drawn here, in the trial's
context, so a responder never sees which it was.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from study.probes import get_probe
from study.probes.base import LAPSE_RATE, Probe, ProbeResponse, ProbeTrial
from teleop_core.progress import Progress, no_progress

CONFIRM_RAD = 0.3
"""A device answer is confirmed when the dial is turned past this angle (rad) either way."""
DEVICE_TIMEOUT_S = 10.0
DEVICE_RATE_HZ = 100.0


class Responder(Protocol):
    driver: str

    def respond(
        self, probe: Probe, stimulus: float, context: Mapping[str, float]
    ) -> ProbeResponse: ...


@dataclass
class SimulatedResponder:
    traits: Any
    """A `ParticipantTraits`."""
    rng: np.random.Generator
    lapse_rate: float = LAPSE_RATE
    driver: str = "simulated"

    def respond(self, probe: Probe, stimulus: float, context: Mapping[str, float]) -> ProbeResponse:
        return probe.answer(stimulus, self.traits, context, self.rng, self.lapse_rate)


@dataclass
class KeyboardResponder:
    read_key: Callable[[], str]
    """Blocks until the participant's key (or a typed value and Enter)."""
    show: Callable[[str], None]
    clock: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep
    driver: str = "keyboard"

    def respond(self, probe: Probe, stimulus: float, context: Mapping[str, float]) -> ProbeResponse:
        self.show(probe.keyboard_prompt(stimulus, context))
        cue = probe.keyboard_cue(stimulus, context)
        if cue.moving:  # a marker moving at 10 Hz until the stimulus (it stops)
            for _ in range(round(cue.delay_s * 10)):
                self.show(".")
                self.sleep(0.1)
        elif cue.delay_s > 0:
            self.sleep(cue.delay_s)
        if cue.text:
            self.show(cue.text)
        start = self.clock()
        while True:
            key = self.read_key()
            answer = probe.from_key(stimulus, key, self.clock() - start, context)
            if answer is not None:
                return answer
            self.show(f"{key!r} is not an answer here; {probe.keyboard_prompt(stimulus, context)}")


@dataclass
class DeviceResponder:
    exchange: Callable[[float], Any]
    """The dial unit's exchange: a q-current command, A -> a `UnitState` (t_ms, angle_rad,
    speed_rad_s, iq_ma, joystick); `HardwareDriver.exchange` on the real dial."""
    current_for: Callable[[Probe, float, Mapping[str, float], float], float] = (
        lambda probe, stimulus, context, t_s: 0.0
    )
    """The current to render at t_s into the trial, A (the probe's torque on the hand:
    the force step in its interval, the comfort ramp); none by default."""
    max_rotation_rate_rad_s: float = math.pi / 2
    driver: str = "hardware"

    def samples(
        self, probe: Probe, stimulus: float, context: Mapping[str, float]
    ) -> Iterator[list[float]]:
        t0 = rotation = None
        last_t = 0.0
        for _ in range(int(DEVICE_TIMEOUT_S * DEVICE_RATE_HZ)):
            t_s = 0.0 if t0 is None else last_t
            state = self.exchange(self.current_for(probe, stimulus, context, t_s))
            t0 = state.t_ms if t0 is None else t0
            now = (state.t_ms - t0) / 1000.0
            # the joystick sets the tip's rotation rate; the angle is its integral
            rotation = 0.0 if rotation is None else rotation
            rotation += state.joystick * self.max_rotation_rate_rad_s * (now - last_t)
            last_t = now
            pressed = abs(state.angle_rad) > CONFIRM_RAD
            yield [now, state.angle_rad, rotation, 1.0 if pressed else 0.0]
            if pressed:
                return

    def respond(self, probe: Probe, stimulus: float, context: Mapping[str, float]) -> ProbeResponse:
        rows = np.array(list(self.samples(probe, stimulus, context)), float).reshape(-1, 4)
        return probe.from_device(stimulus, rows, context)


def run_probe(
    name: str,
    n_trials: int,
    responder: Responder,
    rng: np.random.Generator,
    context: Mapping[str, float] | None = None,
    progress: Progress = no_progress,
    on_trial: Callable[[ProbeTrial], None] = lambda trial: None,
) -> list[ProbeTrial]:
    """`n_trials` trials of probe `name` answered by `responder`; `on_trial` sees each
    trial as soon as it is answered."""
    probe = get_probe(name)
    base = dict(context or {})
    procedure = probe.procedure(n_trials, base, rng)
    trials = []
    for k in range(n_trials):
        stimulus = procedure.next_stimulus()
        trial_context = dict(base)
        if probe.forced_choice:
            trial_context["interval"] = float(rng.integers(1, 3))
        answer = responder.respond(probe, stimulus, trial_context)
        procedure.record(stimulus, answer)
        trials.append(
            ProbeTrial(
                name, k, stimulus, answer.response, answer.correct, trial_context, responder.driver
            )
        )
        on_trial(trials[-1])
        progress(name, k + 1, n_trials)
    return trials
