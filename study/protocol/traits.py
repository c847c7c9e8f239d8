"""The simulated people's traits and their distributions per experience group.

Every task's simulated participant is the same person (speed, reaction, steering error,
caution, what it notices and what it accepts) doing that task; the traits are therefore
the study's, not a task's, and live here below the tasks (`study.tasks.*`), the session
runner and the participant fit. Group distributions (mean, sd; truncated to plausible
ranges) are assumptions shaped by [endovascular], IV-D, not measured values; a fitted model
(`study.protocol.participant_model`) replaces them where one is given.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np

from study.errors import StudyInputError
from study.protocol.design import DEFAULT_GROUPS

GROUPS = DEFAULT_GROUPS


@dataclass(frozen=True)
class GroupProfile:
    """Group-level (mean, sd) of each trait."""

    preferred_speed_m_s: tuple[float, float]
    reaction_s: tuple[float, float]
    steering_error_rad: tuple[float, float]
    caution: tuple[float, float]
    """0..1: how much it slows near the ostium and yields to felt resistance."""
    haptic_threshold_n_m: tuple[float, float]
    """Rise of the torque on the hand it notices. At the paper's gain (0.02 N m/N) the
    groups' means are 0.205 / 0.185 / 0.165 N of follower force, 0.192 N over a 20/8/8
    study: the JND for force in endovascular tasks that [endovascular] designs for (its
    ref. [11]); the spread within a group (SD about a fifth of the mean) and the order of
    the groups are assumptions. The force-threshold probe measures it
    (`study.probes.force_threshold`)."""
    visual_stall_s: tuple[float, float]
    """How long the tip must stand still on screen before it is taken as an obstacle."""
    comfort_torque_n_m: tuple[float, float]
    """Resistance on the hand it accepts before pushing more gently (HV)."""


PROFILES: dict[str, GroupProfile] = {
    "outsider": GroupProfile(
        preferred_speed_m_s=(0.012, 0.003),
        reaction_s=(0.32, 0.06),
        steering_error_rad=(0.45, 0.10),
        caution=(0.35, 0.10),
        haptic_threshold_n_m=(0.0041, 0.0008),
        visual_stall_s=(0.70, 0.15),
        comfort_torque_n_m=(0.010, 0.0015),
    ),
    "novice": GroupProfile(
        preferred_speed_m_s=(0.014, 0.003),
        reaction_s=(0.28, 0.05),
        steering_error_rad=(0.32, 0.08),
        caution=(0.50, 0.10),
        haptic_threshold_n_m=(0.0037, 0.0007),
        visual_stall_s=(0.55, 0.12),
        comfort_torque_n_m=(0.009, 0.0012),
    ),
    "expert": GroupProfile(
        preferred_speed_m_s=(0.017, 0.003),
        reaction_s=(0.22, 0.04),
        steering_error_rad=(0.25, 0.05),
        caution=(0.65, 0.10),
        haptic_threshold_n_m=(0.0033, 0.0006),
        visual_stall_s=(0.40, 0.10),
        comfort_torque_n_m=(0.008, 0.0010),
    ),
}


@dataclass(frozen=True)
class ParticipantTraits:
    group: str
    preferred_speed_m_s: float
    reaction_s: float
    steering_error_rad: float
    caution: float
    haptic_threshold_n_m: float
    visual_stall_s: float
    comfort_torque_n_m: float

    def to_dict(self) -> dict[str, float | str]:
        return asdict(self)


TRAIT_BOUNDS: dict[str, tuple[float, float]] = {
    "preferred_speed_m_s": (0.005, 0.03),
    "reaction_s": (0.12, 0.6),
    "steering_error_rad": (0.05, 0.8),
    "caution": (0.0, 1.0),
    "haptic_threshold_n_m": (0.002, 0.02),
    "visual_stall_s": (0.2, 1.5),
    "comfort_torque_n_m": (0.003, 0.02),
}
"""Plausible range of each trait: a drawn value is clipped into it."""
TRAITS = tuple(TRAIT_BOUNDS)

TRIAL_CV: dict[str, float] = {
    "preferred_speed_m_s": 0.10,
    "reaction_s": 0.15,
    "haptic_threshold_n_m": 0.15,
    "visual_stall_s": 0.20,
    "comfort_torque_n_m": 0.10,
}
"""A person's trial-to-trial coefficient of variation of each trait that varies from
one trial to the next (assumption, shaped by the motor-control literature: the
within-person CV of a repeated movement's speed and time is 5-15 %, of a simple
reaction time 10-20 %, of a force detection threshold 10-20 %; the README states the
measures' CV this gives). Each trial draws the person's state as the trait times a
lognormal factor of mean 1 from the trial's own generator; the steering error and the
caution stay the person's (the aim is drawn per attempt already)."""


def trial_state(traits: ParticipantTraits, rng: np.random.Generator) -> ParticipantTraits:
    """The person as they are in one trial: each trait in `TRIAL_CV` times a lognormal
    factor of mean 1 and that CV, clipped into `TRAIT_BOUNDS`."""
    values: dict[str, Any] = traits.to_dict()
    for name, cv in TRIAL_CV.items():
        # log factor ~ N(-s^2 / 2, s^2), s^2 = log(1 + cv^2): E[factor] = 1, CV = cv
        s = math.sqrt(math.log1p(cv * cv))
        lo, hi = TRAIT_BOUNDS[name]
        values[name] = float(np.clip(values[name] * math.exp(rng.normal(-s * s / 2, s)), lo, hi))
    return ParticipantTraits(**values)


def draw_traits(
    group: str, rng: np.random.Generator, profiles: dict[str, GroupProfile] | None = None
) -> ParticipantTraits:
    """One participant's traits from the group's distributions: `profiles` (a fitted
    `study.protocol.participant_model.ParticipantModel`'s), else `PROFILES`."""
    profiles = PROFILES if profiles is None else profiles
    if group not in profiles:
        raise StudyInputError(
            f"no simulated participant profile for group {group!r}; expected one of "
            f"{', '.join(profiles)} (a group of the design's own is run by a person at the "
            "keyboard or on the hardware, or drawn from a participant model fitted to it)"
        )
    p = profiles[group]
    values = {
        name: float(np.clip(rng.normal(*getattr(p, name)), lo, hi))
        for name, (lo, hi) in TRAIT_BOUNDS.items()
    }
    return ParticipantTraits(group=group, **values)


class TraitModel(Protocol):
    """What `simulated_participant` uses of a fitted model
    (`study.protocol.participant_model.ParticipantModel`, which imports this module)."""

    def draw(self, group: str, rng: np.random.Generator) -> ParticipantTraits: ...


def simulated_participant(
    group: str, seed: int, model: TraitModel | None = None
) -> ParticipantTraits:
    """The traits of the participant a seed draws from `group` (same seed, same person),
    from the fitted `model`'s distributions when one is given."""
    rng = np.random.default_rng([seed, 0x5EED])
    return draw_traits(group, rng) if model is None else model.draw(group, rng)
