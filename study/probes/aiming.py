"""Aiming precision: the roadmap shows a branch's ostium at a random angle; the
participant turns the angled guidewire tip towards it with the rotation joystick and
confirms, without advancing.

This is the LCCA participant's first attempt at the ostium in isolation: its aim is off
by N(0, `steering_error_rad`) (`SimulatedParticipant._new_attempt`).

Simulated participant: the angular error = N(0, steering_error_rad); a lapse confirms
at an angle uniform over +/- pi/2 of the target.

Measurement model: the errors are a mixture of N(0, sigma) and the lapses' uniform
over +/- pi/2, with the lapse share fixed at `LAPSE_RATE`; sigma by maximum likelihood
(scipy's bounded scalar search on log sigma), its SE sigma / sqrt(2 n (1 - lapse)), the
normal SD's over the trials that are not lapses. The median absolute error (robust but
37 % efficient) needed 2.7 times the trials for the same SE.
"""

from __future__ import annotations

import math
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
)


class Aiming:
    name = "aiming"
    trait = "steering_error_rad"
    default_trials = 30
    stimulus_unit = "rad"
    response_unit = "rad"
    description = "turn the tip towards a target on the roadmap and confirm"
    forced_choice = False

    def procedure(
        self, n_trials: int, context: Mapping[str, float], rng: np.random.Generator
    ) -> FixedProcedure:
        # the target's angle, rad
        return FixedProcedure(rng.uniform(-math.pi, math.pi, n_trials))

    def answer(
        self,
        stimulus: float,
        traits: Any,
        context: Mapping[str, float],
        rng: np.random.Generator,
        lapse_rate: float = LAPSE_RATE,
    ) -> ProbeResponse:
        if rng.random() < lapse_rate:
            return ProbeResponse(float(stimulus + rng.uniform(-math.pi / 2, math.pi / 2)))
        return ProbeResponse(float(stimulus + rng.normal(0.0, traits.steering_error_rad)))

    def estimate(
        self, trials: Sequence[ProbeTrial], known: Mapping[str, TraitEstimate]
    ) -> TraitEstimate | None:
        errors = np.array(
            [
                math.remainder(t.response - t.stimulus, 2 * math.pi)
                for t in trials
                if t.response is not None and t.stimulus is not None
            ]
        )
        if len(errors) < 5:
            return None
        # lazy: scipy.optimize costs 0.4 s at start-up
        from scipy.optimize import minimize_scalar

        # lazy: scipy.stats costs 0.7 s at start-up
        from scipy.stats import norm

        lapse = LAPSE_RATE
        outside = np.abs(errors) > math.pi / 2  # only a normal error can land there

        def nll(log_sigma: float) -> float:
            dens = (1 - lapse) * norm.pdf(errors, 0.0, math.exp(log_sigma))
            dens = dens + np.where(outside, 0.0, lapse / math.pi)
            return -float(np.log(np.maximum(dens, 1e-300)).sum())

        best = minimize_scalar(nll, bounds=(math.log(1e-3), math.log(3.0)), method="bounded")
        sigma = math.exp(best.x)
        se = sigma / math.sqrt(2 * len(errors) * (1 - lapse))
        return TraitEstimate(self.trait, sigma, se, len(errors))

    def keyboard_prompt(self, stimulus: float, context: Mapping[str, float]) -> str:
        return (
            f"Target at {math.degrees(stimulus):+.0f} deg: type the tip's angle in "
            "degrees and press Enter"
        )

    def keyboard_cue(self, stimulus: float, context: Mapping[str, float]) -> KeyboardCue:
        return KeyboardCue()

    def from_key(
        self, stimulus: float, key: str, elapsed_s: float, context: Mapping[str, float]
    ) -> ProbeResponse | None:
        try:
            return ProbeResponse(math.radians(float(key)))
        except ValueError:
            return None

    def from_device(
        self, stimulus: float, samples: np.ndarray, context: Mapping[str, float]
    ) -> ProbeResponse:
        row = first_press(samples)
        return ProbeResponse(None if row is None else float(samples[row, 2]))


PROBE = Aiming()
