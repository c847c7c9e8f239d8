"""The haptic force-discrimination threshold on the dial, by QUEST+ (two intervals).

Each trial renders the dial's hold torque twice, once with an added follower-equivalent
force step dF (N) at the design's HV haptic gain G (N m/N: the hand feels G * dF more);
the participant says which interval was stronger. QUEST+ (Watson 2017, the `questplus`
package) picks each dF to minimise the expected entropy of the posterior over the
psychometric function's parameters: a cumulative normal in dF with mean `threshold_n`
(the 75 % point over the 50 % guess rate), spread `sd_n` and lapse rate, each on a grid.

Simulated participant: it notices the step when the torque rise G * dF plus sensory noise
passes its `haptic_threshold_n_m` (the trait the LCCA participant acts on): P(notice) =
Phi((G dF - theta) / (RELATIVE_NOISE theta)); it picks the stronger interval when it
noticed, guesses otherwise, and lapses (guesses) at the lapse rate. So its 75 % point
is dF = theta / G.

Measurement model: the trait is G times the threshold; its estimate and SE are G times
the posterior mean and SD of `threshold_n`, marginalised over the spread and the lapse
rate, computed again from the stored trials (not from the run's state), so that the fit
reads the same number from any copy of the data. `psignifit` was not taken: the QUEST+
posterior already is the Bayesian psychometric fit on this grid.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy.stats import norm

from study.probes.base import (
    LAPSE_RATE,
    KeyboardCue,
    ProbeResponse,
    ProbeTrial,
    TraitEstimate,
    first_press,
)

STIMULI_N = np.geomspace(0.02, 1.5, 41)
"""The force steps QUEST+ may choose, N (follower-equivalent)."""
THRESHOLD_GRID_N = np.geomspace(0.03, 1.2, 61)
SD_GRID_N = np.array([0.01, 0.02, 0.04, 0.08, 0.16])
LAPSE_GRID = np.array([0.01, 0.04, 0.08])
RELATIVE_NOISE = 0.25
"""A simulated participant's sensory noise, as a share of its threshold (a Weber-like
spread: the psychometric function's SD a quarter of its threshold; assumption)."""
PAPER_GAIN_N_M_PER_N = 0.02
"""The dial's gain when the design names none for HV (`HapticParams`, [endovascular])."""


def _quest(stimuli: np.ndarray = STIMULI_N) -> Any:
    # lazy: questplus costs 0.4 s at start-up
    from questplus import QuestPlus

    return QuestPlus(
        stim_domain={"intensity": stimuli},
        param_domain={
            "mean": THRESHOLD_GRID_N,
            "sd": SD_GRID_N,
            "lower_asymptote": 0.5,
            "lapse_rate": LAPSE_GRID,
        },
        outcome_domain={"response": ["Correct", "Incorrect"]},
        func="norm_cdf",
        stim_scale="linear",
    )


class QuestProcedure:
    """QUEST+'s next force step and its update."""

    def __init__(self) -> None:
        self.quest = _quest()

    def next_stimulus(self) -> float:
        return float(self.quest.next_stim["intensity"])

    def record(self, stimulus: float, answer: ProbeResponse) -> None:
        if answer.correct is None:
            return
        outcome = "Correct" if answer.correct else "Incorrect"
        self.quest.update(stim={"intensity": stimulus}, outcome={"response": outcome})


class ForceThreshold:
    name = "force_threshold"
    trait = "haptic_threshold_n_m"
    default_trials = 60
    stimulus_unit = "N"
    response_unit = "interval"
    description = "force-discrimination threshold on the dial (2 intervals, QUEST+)"
    forced_choice = True

    def procedure(
        self, n_trials: int, context: Mapping[str, float], rng: np.random.Generator
    ) -> QuestProcedure:
        return QuestProcedure()

    def answer(
        self,
        stimulus: float,
        traits: Any,
        context: Mapping[str, float],
        rng: np.random.Generator,
        lapse_rate: float = LAPSE_RATE,
    ) -> ProbeResponse:
        gain = context.get("gain_n_m_per_n", PAPER_GAIN_N_M_PER_N)
        theta = traits.haptic_threshold_n_m
        interval = int(context.get("interval", 1))
        # P(notice) = Phi((G dF - theta) / (noise theta))
        noticed = rng.random() < norm.cdf((gain * stimulus - theta) / (RELATIVE_NOISE * theta))
        if rng.random() < lapse_rate or not noticed:
            chosen = int(rng.integers(1, 3))
        else:
            chosen = interval
        return ProbeResponse(float(chosen), chosen == interval)

    def estimate(
        self, trials: Sequence[ProbeTrial], known: Mapping[str, TraitEstimate]
    ) -> TraitEstimate | None:
        used = [t for t in trials if t.correct is not None and t.stimulus is not None]
        if len(used) < 10:
            return None
        # the posterior over every stored step (QUEST+'s grid takes any intensity)
        quest = _quest(np.unique([t.stimulus for t in used]))
        for t in used:
            outcome = "Correct" if t.correct else "Incorrect"
            quest.update(stim={"intensity": t.stimulus}, outcome={"response": outcome})
        posterior = quest.posterior
        marginal = posterior.sum(dim=[d for d in posterior.dims if d != "mean"])
        grid = marginal["mean"].to_numpy()
        p = marginal.to_numpy() / marginal.to_numpy().sum()
        mean = float((p * grid).sum())
        sd = float(np.sqrt((p * (grid - mean) ** 2).sum()))
        gains = {t.context.get("gain_n_m_per_n", PAPER_GAIN_N_M_PER_N) for t in used}
        if len(gains) != 1:
            return None  # steps at different gains are not one threshold in N m
        gain = gains.pop()
        return TraitEstimate(self.trait, gain * mean, gain * sd, len(used))

    def keyboard_prompt(self, stimulus: float, context: Mapping[str, float]) -> str:
        return "Which interval was stronger? 1 or 2"

    def keyboard_cue(self, stimulus: float, context: Mapping[str, float]) -> KeyboardCue:
        return KeyboardCue()

    def from_key(
        self, stimulus: float, key: str, elapsed_s: float, context: Mapping[str, float]
    ) -> ProbeResponse | None:
        if key not in ("1", "2"):
            return None
        return ProbeResponse(float(key), int(key) == int(context.get("interval", 1)))

    def from_device(
        self, stimulus: float, samples: np.ndarray, context: Mapping[str, float]
    ) -> ProbeResponse:
        # the dial turned left (negative) at the press picks interval 1, right picks 2
        row = first_press(samples)
        if row is None:
            return ProbeResponse(None, None)
        chosen = 1 if samples[row, 1] < 0 else 2
        return ProbeResponse(float(chosen), chosen == int(context.get("interval", 1)))


PROBE = ForceThreshold()
