"""Participant effects: how a simulated person changes over a session, beyond chance.

A simulated person's traits (`participants.ParticipantTraits`) are theirs for the whole
session, and each trial draws their state about them (`participants.trial_state`).
Real people also change in a way that follows the session's course. This module holds
the families the participant fit may add when its residual shows such structure
(`study.analysis.participant_fit.effects`), each a multiplier on some traits as a
function of where a trial lies in the session (`TrialPlace`):

- `practice` (learning over trials): the preferred speed is divided by
  1 + slowing * exp(-position / decay_trials): the first measured trial is `slowing`
  slower (0.5: 50 %), and the slowing decays over the session's trials;
- `fatigue`: the preferred speed times exp(-rate * position) and the reaction time
  times exp(rate * position): slower and later as the session goes on;
- `carry_over` of the first condition into the second: in the second block, when it
  follows the other condition, the preferred speed and the time the tip must stall on
  screen before it counts as an obstacle are both times (1 - share), with one share per
  direction (`vo_after_hv`: VO pushed more gently after HV first, as if still feeling
  the force; `hv_after_vo`). The fit moves one direction and holds the other at 0: with
  two condition orders the data tell only their difference, and both shares equal
  would be a period effect, which is practice's (or fatigue's) to explain;
- `gentle_carry_over`: the same place, but what carries over is how hard the person
  pushes, not how fast they go: the caution times (1 + share) and the torque the person
  accepts on the dial (`comfort_torque_n_m`) times (1 - share), the traits that set the
  forces near contact (a share > 0: gentler; `gentler_vo_after_hv`: VO pushed more
  gently after HV first, as if still feeling the force; `gentler_hv_after_vo`). The
  preferred speed and the stall time stay, so the completion time moves only as far as
  the caution's slowing moves it (in LCCA the caution also sets the approach and entry
  speeds, so there the time follows in part; the emulator says how far; on the forces
  alone it is `force_carry_over`); one direction at a time, as above;
- `force_carry_over`: the same place, an effect on the forces alone: the person aims
  the tip at the ostium with more care (`steering_error_rad` times (1 - share);
  `softer_vo_after_hv`: in VO after HV first, as if the felt resistance had taught
  what a caught tip costs; `softer_hv_after_vo`) and advances a little slower while
  doing so (`preferred_speed_m_s` times (1 - share)^0.1). Fewer tips catch an
  ostium's edge, where the peak forces of a trial are set; the failed attempts saved
  make up for the slower advance (the exponent is set so on LCCA's simulator), so the
  completion time keeps its course;
- `time_carry_over`: the same place, an effect on the time alone: the person goes
  slower (`preferred_speed_m_s` times (1 - share); `slower_vo_after_hv`,
  `slower_hv_after_vo`) and takes as much longer to give up pushing on a stalled or
  resisting tip (`visual_stall_s` and `haptic_threshold_n_m` divided by
  (1 - share)^1.5): the slower push builds the force into an obstacle more slowly and
  drags less, and the later back-off makes up for both (the exponent is set so on
  LCCA's simulator), so the peak forces stay;
- `unexplained_person`: a person no trait setting reproduces. Reported, never absorbed:
  it has no multiplier, and a simulation never draws it.

Why multipliers on traits rather than offsets on the measures: the simulated
participant carries them through the same physics as everything else, so a simulation
drawn from a fitted model (`study simulate`, `run`, `demo`, `power`, campaigns) shows
the effect in every measure and sample feature, and the fit predicts its consequence on
the emulator of the traits. The shapes are the common ones of the motor-learning
literature (an exponential approach to a plateau for practice) kept to one or two
parameters each, so that a study of a few dozen people tells them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from study.errors import StudyInputError
from study.protocol.traits import TRAIT_BOUNDS, ParticipantTraits

FAMILIES: dict[str, tuple[str, ...]] = {
    "practice": ("slowing", "decay_trials"),
    "fatigue": ("rate",),
    "carry_over": ("vo_after_hv", "hv_after_vo"),
    "gentle_carry_over": ("gentler_vo_after_hv", "gentler_hv_after_vo"),
    "force_carry_over": ("softer_vo_after_hv", "softer_hv_after_vo"),
    "time_carry_over": ("slower_vo_after_hv", "slower_hv_after_vo"),
}
"""Each family the fit may add, with its parameters' names."""
UNEXPLAINED = "unexplained_person"
"""The family of a person no trait setting reproduces: reported, never simulated."""
BOUNDS: dict[str, tuple[float, float]] = {
    "slowing": (0.0, 3.0),
    "decay_trials": (0.3, 20.0),
    "rate": (-0.1, 0.1),
    "vo_after_hv": (-0.6, 0.6),
    "hv_after_vo": (-0.6, 0.6),
    "gentler_vo_after_hv": (-0.6, 0.6),
    "gentler_hv_after_vo": (-0.6, 0.6),
    "softer_vo_after_hv": (-0.6, 0.6),
    "softer_hv_after_vo": (-0.6, 0.6),
    "slower_vo_after_hv": (-0.5, 0.5),
    "slower_hv_after_vo": (-0.5, 0.5),
}
"""Each parameter's admissible range (a fit stays inside; a file outside is refused)."""


@dataclass(frozen=True)
class TrialPlace:
    """Where a trial lies in a person's session of one task."""

    position: int
    """0, 1, ... over the person's measured trials of the task in the order they run
    (a practice trial counts back from its block's first measured trial)."""
    block: int
    """0 in the first condition's block, 1 in the second."""
    condition: str
    first_condition: str


@dataclass(frozen=True)
class ParticipantEffect:
    """One effect: its family, parameters and the groups it applies to."""

    family: str
    parameters: Mapping[str, float]
    groups: tuple[str, ...] = ()
    """The experience groups it applies to (empty: every group)."""
    intervals: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    """95 % interval of each parameter, where fitted."""

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise StudyInputError(
                f"participant effect {self.family!r}; expected one of {', '.join(FAMILIES)}"
            )
        for name in FAMILIES[self.family]:
            value = self.parameters.get(name)
            lo, hi = BOUNDS[name]
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not (math.isfinite(value) and lo <= value <= hi)
            ):
                raise StudyInputError(
                    f"participant effect {self.family}: {name} = {value!r}; expected a "
                    f"number in [{lo:g}, {hi:g}]"
                )

    def factors(self, place: TrialPlace) -> dict[str, float]:
        """trait -> the multiplier this effect puts on it at `place`."""
        p = self.parameters
        if self.family == "practice":
            slow = 1.0 + p["slowing"] * math.exp(-place.position / p["decay_trials"])
            return {"preferred_speed_m_s": 1.0 / slow}
        if self.family == "fatigue":
            grow = math.exp(p["rate"] * place.position)
            return {"preferred_speed_m_s": 1.0 / grow, "reaction_s": grow}
        # carry-overs: only a second block that follows the other condition
        if place.block == 0 or place.condition == place.first_condition:
            return {}
        vo_name, hv_name = FAMILIES[self.family]
        share = p[vo_name] if place.condition == "VO" else p[hv_name]
        if self.family == "gentle_carry_over":
            return {"caution": 1.0 + share, "comfort_torque_n_m": 1.0 - share}
        if self.family == "force_carry_over":
            return {"steering_error_rad": 1.0 - share, "preferred_speed_m_s": (1.0 - share) ** 0.1}
        if self.family == "time_carry_over":
            # the later back-off: (1 - share)^-1.5 keeps LCCA's simulated peak forces
            later = (1.0 - share) ** -1.5
            return {
                "preferred_speed_m_s": 1.0 - share,
                "visual_stall_s": later,
                "haptic_threshold_n_m": later,
            }
        return {"preferred_speed_m_s": 1.0 - share, "visual_stall_s": 1.0 - share}

    def applies_to(self, group: str) -> bool:
        return not self.groups or group in self.groups

    def to_dict(self) -> dict[str, Any]:
        return {
            "family": self.family,
            "parameters": {
                name: {
                    "value": float(self.parameters[name]),
                    **(
                        {"ci95": [float(v) for v in self.intervals[name]]}
                        if name in self.intervals
                        else {}
                    ),
                }
                for name in FAMILIES[self.family]
            },
            "groups": list(self.groups),
        }


def effect_from_dict(data: Any, where: str) -> ParticipantEffect | None:
    """A `ParticipantEffect` from MODEL.json's `participant_effects` entry (None for an
    `unexplained_person`, which is reported only), or one line."""
    if not isinstance(data, dict):
        raise StudyInputError(f"{where} = {data!r}; expected an object with a family")
    family = data.get("family")
    if family == UNEXPLAINED:
        return None
    if family not in FAMILIES:
        raise StudyInputError(
            f"{where}.family = {family!r}; expected one of {', '.join([*FAMILIES, UNEXPLAINED])}"
        )
    params = data.get("parameters")
    if not isinstance(params, dict):
        raise StudyInputError(f"{where}.parameters = {params!r}; expected an object")
    values: dict[str, Any] = {}  # checked by ParticipantEffect
    for name in FAMILIES[family]:
        value = params.get(name)
        values[name] = value.get("value") if isinstance(value, dict) else value
    groups = data.get("groups", [])
    if not isinstance(groups, list) or not all(isinstance(g, str) for g in groups):
        raise StudyInputError(f"{where}.groups = {groups!r}; expected a list of group names")
    try:
        return ParticipantEffect(family, values, tuple(groups))
    except StudyInputError as exc:
        raise StudyInputError(f"{where}: {exc}") from None


def apply_effects(
    traits: ParticipantTraits, effects: Sequence[ParticipantEffect], place: TrialPlace | None
) -> ParticipantTraits:
    """The person's traits at `place` with every effect of their group applied (clipped
    into `TRAIT_BOUNDS`); unchanged without effects or a place."""
    if not effects or place is None:
        return traits
    scale: dict[str, float] = {}
    for effect in effects:
        if effect.applies_to(traits.group):
            for trait, factor in effect.factors(place).items():
                scale[trait] = scale.get(trait, 1.0) * factor
    if not scale:
        return traits
    changed = {}
    for trait, factor in scale.items():
        lo, hi = TRAIT_BOUNDS[trait]
        changed[trait] = min(max(getattr(traits, trait) * factor, lo), hi)
    return replace(traits, **changed)


def session_place(
    conditions: Sequence[str],
    block: int,
    trial_index: int,
    n_trials: int,
    practice: bool = False,
    n_practice: int = 0,
) -> TrialPlace:
    """The place of a trial in a session whose blocks of the task run `conditions` in
    order, `n_trials` measured trials each (`block`: index into `conditions`)."""
    first = block * n_trials
    position = first - n_practice + trial_index if practice else first + trial_index
    return TrialPlace(position, block, conditions[block], conditions[0])
