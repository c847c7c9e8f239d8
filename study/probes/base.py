"""What every probe shares: the `Probe` protocol, one probe trial, a trait's estimate.

A probe is a short psychophysical measurement run before a task's first block whose
result tells one trait of the participant model (`study.protocol.traits`) that the
task's trials tell weakly. A probe owns four things, so that nothing outside its module
names it:

- its procedure: which stimulus comes next (`procedure`), adaptive or fixed;
- a simulated participant's answer from its traits, with a lapse rate and response
  noise (`answer`);
- its measurement model: the trait's estimate and standard error from the stored trials
  (`estimate`), which the participant fit uses beside the task's data;
- how the keyboard and a hardware device give its answer (`keyboard_prompt`,
  `from_key`, `from_device`).

Stimuli and responses are stored as plain numbers in SI units (`ProbeTrial`), so `db`
stores them without knowing any probe.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from teleop_core._typing import Float1D

DEVICE_COLUMNS = ("t_s", "dial_angle_rad", "rotation_rad", "button")
"""A hardware probe trial's samples, one row each (`Probe.from_device`): time since the
stimulus, s; the dial's angle and the rotation joystick's, rad; the confirm button (0/1)."""
LAPSE_RATE = 0.03
"""Share of a simulated participant's probe trials answered without regard to the
stimulus (a guess, a premature or late press): an assumption, in the 1-5 % range that
psychometric fits allow for (Wichmann & Hill 2001)."""


@dataclass(frozen=True)
class ProbeResponse:
    """One answer to one stimulus."""

    response: float | None
    """The probe's response in its unit (a time in s, an angle in rad, a torque in N m,
    the chosen interval 1/2); None when the participant gave none."""
    correct: bool | None = None
    """For forced-choice probes: whether the answer was right; otherwise None."""


@dataclass(frozen=True)
class ProbeTrial:
    """One stored probe trial."""

    probe: str
    trial_index: int
    stimulus: float | None
    response: float | None
    correct: bool | None = None
    context: Mapping[str, float] = field(default_factory=dict)
    """The settings the trial ran with that its measurement model needs (e.g. the
    dial's haptic gain, N m/N; a torque ramp's rate, N m/s)."""
    driver: str = "simulated"


@dataclass(frozen=True)
class TraitEstimate:
    """A trait told by a probe: its estimate and standard error, in the trait's unit."""

    trait: str
    value: float
    se: float
    trials: int
    """Probe trials that entered the estimate."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.value) and np.isfinite(self.se) and self.se > 0):
            raise ValueError(
                f"{self.trait}: estimate {self.value} +/- {self.se}; expected finite, se > 0"
            )


@dataclass(frozen=True)
class KeyboardCue:
    """How a terminal presents a stimulus: after the prompt, wait `delay_s` (showing a
    moving marker meanwhile when `moving`), then show `text`; the response time counts
    from the end of the wait."""

    delay_s: float = 0.0
    text: str = ""
    moving: bool = False


class Procedure(Protocol):
    """A probe's run: the next stimulus, given the answers so far."""

    def next_stimulus(self) -> float: ...

    def record(self, stimulus: float, answer: ProbeResponse) -> None: ...


@runtime_checkable
class Probe(Protocol):
    """A probe: see the module docstring."""

    name: str
    """Its registry name (an identifier of at most 32 characters)."""
    trait: str
    """The `ParticipantTraits` field it tells."""
    default_trials: int
    stimulus_unit: str
    response_unit: str
    description: str
    forced_choice: bool
    """Two intervals, one holding the stimulus (`context["interval"]`, 1 or 2, drawn by
    the runner); the answer is the interval chosen. A probe whose measurement model takes
    another probe's trait names it in an optional `needs` tuple (estimated first)."""

    def procedure(
        self, n_trials: int, context: Mapping[str, float], rng: np.random.Generator
    ) -> Procedure: ...

    def answer(
        self,
        stimulus: float,
        traits: Any,
        context: Mapping[str, float],
        rng: np.random.Generator,
        lapse_rate: float = LAPSE_RATE,
    ) -> ProbeResponse: ...

    def estimate(
        self, trials: Sequence[ProbeTrial], known: Mapping[str, TraitEstimate]
    ) -> TraitEstimate | None: ...

    def keyboard_prompt(self, stimulus: float, context: Mapping[str, float]) -> str: ...

    def keyboard_cue(self, stimulus: float, context: Mapping[str, float]) -> KeyboardCue: ...

    def from_key(
        self, stimulus: float, key: str, elapsed_s: float, context: Mapping[str, float]
    ) -> ProbeResponse | None: ...

    def from_device(
        self, stimulus: float, samples: np.ndarray, context: Mapping[str, float]
    ) -> ProbeResponse: ...


class FixedProcedure:
    """A procedure whose stimuli are drawn up front (the non-adaptive probes)."""

    def __init__(self, stimuli: Sequence[float] | Float1D) -> None:
        self._stimuli = list(stimuli)
        self._k = 0

    def next_stimulus(self) -> float:
        stimulus = self._stimuli[self._k % len(self._stimuli)]
        self._k += 1
        return float(stimulus)

    def record(self, stimulus: float, answer: ProbeResponse) -> None:
        return None


def robust_location(values: np.ndarray) -> tuple[float, float]:
    """(median, its standard error) of `values`: the median's asymptotic SE for normal
    data, sqrt(pi / 2) * sigma / sqrt(n), with sigma from the median absolute deviation
    (1.4826 MAD), so that a lapse (an anticipation, a late press) moves neither."""
    values = np.asarray(values, float)
    median = float(np.median(values))
    sigma = 1.4826 * float(np.median(np.abs(values - median)))
    return median, max(np.sqrt(np.pi / 2) * sigma / np.sqrt(len(values)), 1e-6)


def first_press(samples: np.ndarray) -> int | None:
    """The row of the first confirm press in a device trial's samples, or None."""
    pressed = np.flatnonzero(np.asarray(samples)[:, 3] > 0.5)
    return int(pressed[0]) if len(pressed) else None
