"""Comfort torque: the participant holds the dial pushed forward while the resistance
on it rises slowly from zero (a ramp of `RAMP_N_M_S`); it presses when it would push
more gently (the method of limits, ascending).

This is the HV participant's `comfort_torque_n_m` in isolation: the resistance beyond
which it eases off.

Simulated participant: it decides at comfort_torque * exp(N(0, LOG_SD)) and presses
`reaction_s` later, so the recorded torque is that plus the ramp over its reaction; a
lapse presses at a torque uniform over 0-2.5 times its comfort torque.

Measurement model: the median recorded torque minus the ramp times the reaction time the
`reaction_time` probe measured (without it, the profiles' middle reaction time with an
SE covering their range); the SE is the median's and the reaction's combined.
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
from study.probes.stall_detection import FALLBACK_REACTION_S

RAMP_N_M_S = 0.002
"""The resistance's rise, N m/s: slow enough that a reaction adds under a tenth of a
typical comfort torque (0.3 s x 0.002 = 0.0006 N m against about 0.009 N m)."""
LOG_SD = 0.12
"""The judgement's trial-to-trial spread (log scale; assumption)."""


class ComfortTorque:
    name = "comfort_torque"
    trait = "comfort_torque_n_m"
    default_trials = 8
    stimulus_unit = "N m/s"
    response_unit = "N m"
    description = "resistance on the dial at which the participant would push more gently"
    forced_choice = False
    needs = ("reaction_s",)
    """The traits its measurement model takes from other probes (estimated first)."""

    def procedure(
        self, n_trials: int, context: Mapping[str, float], rng: np.random.Generator
    ) -> FixedProcedure:
        return FixedProcedure([context.get("ramp_n_m_s", RAMP_N_M_S)] * n_trials)

    def answer(
        self,
        stimulus: float,
        traits: Any,
        context: Mapping[str, float],
        rng: np.random.Generator,
        lapse_rate: float = LAPSE_RATE,
    ) -> ProbeResponse:
        comfort = traits.comfort_torque_n_m
        if rng.random() < lapse_rate:
            return ProbeResponse(float(rng.uniform(0.0, 2.5 * comfort)))
        react = traits.reaction_s * np.exp(rng.normal(0.0, reaction_time.LOG_SD))
        return ProbeResponse(float(comfort * np.exp(rng.normal(0.0, LOG_SD)) + stimulus * react))

    def estimate(
        self, trials: Sequence[ProbeTrial], known: Mapping[str, TraitEstimate]
    ) -> TraitEstimate | None:
        used = [t for t in trials if t.response is not None and t.stimulus is not None]
        if len(used) < 4:
            return None
        median, se = robust_location(np.array([t.response for t in used]))
        ramp = float(np.median([t.stimulus for t in used]))
        react = known.get("reaction_s")
        r, r_se = (react.value, react.se) if react is not None else FALLBACK_REACTION_S
        return TraitEstimate(
            self.trait, median - ramp * r, float(np.hypot(se, ramp * r_se)), len(used)
        )

    def keyboard_prompt(self, stimulus: float, context: Mapping[str, float]) -> str:
        return "Push the dial; press Enter when the resistance is more than you would push against"

    def keyboard_cue(self, stimulus: float, context: Mapping[str, float]) -> KeyboardCue:
        return KeyboardCue()

    def from_key(
        self, stimulus: float, key: str, elapsed_s: float, context: Mapping[str, float]
    ) -> ProbeResponse | None:
        # the resistance when the key came: the ramp's rate times the time since it began
        return ProbeResponse(float(stimulus * elapsed_s)) if key in ("", " ") else None

    def from_device(
        self, stimulus: float, samples: np.ndarray, context: Mapping[str, float]
    ) -> ProbeResponse:
        row = first_press(samples)
        return ProbeResponse(None if row is None else float(stimulus * samples[row, 0]))


PROBE = ComfortTorque()
