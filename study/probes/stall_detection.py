"""Visual stall detection: a guidewire tip moves on the screen at a steady speed and
stops at a random moment; the participant presses as soon as it sees it has stopped.

This is the LCCA participant's visual obstacle in isolation: it takes the tip as stuck
when it has stood still for `visual_stall_s`, then acts `reaction_s` later.

Simulated participant: response time after the stop = visual_stall_s * exp(N(0,
LOG_SD)) + reaction_s * exp(N(0, reaction LOG_SD)); a lapse presses at a time uniform
over 0.1-2.5 s.

Measurement model: the stall time is the median response (0.1-3 s) minus the reaction
time the `reaction_time` probe measured, its SE the two SEs combined; without that
probe, minus the LCCA profiles' middle reaction time with an SE that holds their whole
range (`FALLBACK_REACTION_S`), so a participant who missed it still has an estimate.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from study.probes import reaction_time
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

LOG_SD = 0.2
"""The stall judgement's trial-to-trial spread (log scale; assumption)."""
FALLBACK_REACTION_S = (0.27, 0.08)
"""(value, SE) subtracted when the reaction-time probe is missing: the middle of the
profiles' group means (0.22-0.32 s) and an SE that covers their spread."""


class StallDetection:
    name = "stall_detection"
    trait = "visual_stall_s"
    default_trials = 20
    stimulus_unit = "s"
    response_unit = "s"
    description = "time to notice that a moving tip on the screen has stopped"
    forced_choice = False
    needs = ("reaction_s",)
    """The traits its measurement model takes from other probes (estimated first)."""

    def procedure(
        self, n_trials: int, context: Mapping[str, float], rng: np.random.Generator
    ) -> FixedProcedure:
        # when the tip stops after it starts moving, s
        return FixedProcedure(rng.uniform(1.5, 4.0, n_trials))

    def answer(
        self,
        stimulus: float,
        traits: Any,
        context: Mapping[str, float],
        rng: np.random.Generator,
        lapse_rate: float = LAPSE_RATE,
    ) -> ProbeResponse:
        if rng.random() < lapse_rate:
            return ProbeResponse(float(rng.uniform(0.1, 2.5)))
        stall = traits.visual_stall_s * np.exp(rng.normal(0.0, LOG_SD))
        react = traits.reaction_s * np.exp(rng.normal(0.0, reaction_time.LOG_SD))
        return ProbeResponse(float(stall + react))

    def estimate(
        self, trials: Sequence[ProbeTrial], known: Mapping[str, TraitEstimate]
    ) -> TraitEstimate | None:
        times = np.array([t.response for t in trials if t.response is not None], float)
        times = times[(times >= 0.1) & (times <= 3.0)]
        if len(times) < 5:
            return None
        median, se = robust_location(times)
        react = known.get("reaction_s")
        r, r_se = (react.value, react.se) if react is not None else FALLBACK_REACTION_S
        return TraitEstimate(self.trait, median - r, float(np.hypot(se, r_se)), len(times))

    def keyboard_prompt(self, stimulus: float, context: Mapping[str, float]) -> str:
        return "Press Enter as soon as the dots stop"

    def keyboard_cue(self, stimulus: float, context: Mapping[str, float]) -> KeyboardCue:
        return KeyboardCue(stimulus, "", moving=True)

    def from_key(
        self, stimulus: float, key: str, elapsed_s: float, context: Mapping[str, float]
    ) -> ProbeResponse | None:
        return ProbeResponse(float(elapsed_s)) if key in ("", " ") else None

    def from_device(
        self, stimulus: float, samples: np.ndarray, context: Mapping[str, float]
    ) -> ProbeResponse:
        row = first_press(samples)
        return ProbeResponse(None if row is None else float(samples[row, 0]))


PROBE = StallDetection()
