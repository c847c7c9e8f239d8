"""Simple reaction time: after a random foreperiod a cue appears on the screen; the
participant presses as soon as it sees it.

Simulated participant: RT = `reaction_s` * exp(N(0, LOG_SD)) (simple visual RTs have a
coefficient of variation of about 10-20 %; assumption); a lapse presses at a time drawn
uniformly over 0.1-1.0 s (an anticipation or a late press).

Measurement model: the trait is the median RT over the presses between 0.1 s (faster
is an anticipation) and 1.5 s; its SE is the median's (`robust_location`), so the
lapses move neither.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from study.probes.base import (
    LAPSE_RATE,
    FixedProcedure,
    KeyboardCue,
    ProbeResponse,
    ProbeTrial,
    TraitEstimate,
    first_press,
    robust_location,
)

LOG_SD = 0.15
VALID_S = (0.1, 1.5)
"""Presses faster than 0.1 s anticipate the cue; slower than 1.5 s missed it."""


def valid_times(trials: Sequence[ProbeTrial]) -> np.ndarray:
    times = np.array([t.response for t in trials if t.response is not None], float)
    return times[(times >= VALID_S[0]) & (times <= VALID_S[1])]


class ReactionTime:
    name = "reaction_time"
    trait = "reaction_s"
    default_trials = 20
    stimulus_unit = "s"
    response_unit = "s"
    description = "simple visual reaction time (press when the cue appears)"
    forced_choice = False

    def procedure(
        self, n_trials: int, context: Mapping[str, float], rng: np.random.Generator
    ) -> FixedProcedure:
        # the foreperiod, s: uniform 1-3 s so that the cue cannot be anticipated
        return FixedProcedure(rng.uniform(1.0, 3.0, n_trials))

    def answer(
        self,
        stimulus: float,
        traits: Any,
        context: Mapping[str, float],
        rng: np.random.Generator,
        lapse_rate: float = LAPSE_RATE,
    ) -> ProbeResponse:
        if rng.random() < lapse_rate:
            return ProbeResponse(float(rng.uniform(0.1, 1.0)))
        return ProbeResponse(float(traits.reaction_s * np.exp(rng.normal(0.0, LOG_SD))))

    def estimate(
        self, trials: Sequence[ProbeTrial], known: Mapping[str, TraitEstimate]
    ) -> TraitEstimate | None:
        times = valid_times(trials)
        if len(times) < 5:
            return None
        median, se = robust_location(times)
        return TraitEstimate(self.trait, median, se, len(times))

    def keyboard_prompt(self, stimulus: float, context: Mapping[str, float]) -> str:
        return "Press Enter as soon as GO appears"

    def keyboard_cue(self, stimulus: float, context: Mapping[str, float]) -> KeyboardCue:
        return KeyboardCue(stimulus, "GO")

    def from_key(
        self, stimulus: float, key: str, elapsed_s: float, context: Mapping[str, float]
    ) -> ProbeResponse | None:
        return ProbeResponse(float(elapsed_s)) if key in ("", " ") else None

    def from_device(
        self, stimulus: float, samples: np.ndarray, context: Mapping[str, float]
    ) -> ProbeResponse:
        row = first_press(samples)
        return ProbeResponse(None if row is None else float(samples[row, 0]))


PROBE = ReactionTime()
