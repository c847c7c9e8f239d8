"""NASA-TLX answers of a simulated participant, from what its block of trials was like.

The answers come from the block's experience, not from the condition label: longer
trials raise temporal demand and effort; wall contacts and repeated attempts raise
frustration and mental demand (watching the screen for the tip stalling) and lower
the self-rated performance; a participant who felt the force (HV) had that cue in the
hand and reports less mental demand for the same block only because it met fewer
obstacles. Each subscale adds the person's own offset (drawn from the seed) and
rating noise, rounded to the form's steps of 5. The 15 pairwise choices follow a
per-person ranking of the subscales, moved a little in each block (so a person's
weights differ between VO and HV), with some inconsistency.
"""

from __future__ import annotations

import numpy as np

from db.models.tlx import TLX_SUBSCALES
from study.protocol.tlx import pair_order

BASE = {
    "mental": 45.0,
    "physical": 20.0,
    "temporal": 35.0,
    "performance": 25.0,
    "effort": 40.0,
    "frustration": 25.0,
}
"""Ratings of an uneventful block (assumption)."""


def block_ratings(
    completion_times_s: list[float],
    wall_contacts: list[int],
    successes: list[bool],
    rng: np.random.Generator,
    offsets: dict[str, float],
    seen_stalls: int = 0,
) -> dict[str, int]:
    """Six ratings (0-100, steps of 5) for one block.

    `seen_stalls` counts the obstacles the participant had to spot on the screen (a
    stalled tip): watching for them is the sustained visual vigilance that haptic
    feedback relieves ([endovascular], IV-D), so it weighs on mental demand and frustration.
    """
    time_s = float(np.mean(completion_times_s)) if completion_times_s else 60.0
    contacts = float(np.sum(wall_contacts))
    failures = sum(1 for s in successes if not s)
    raw = {
        "mental": BASE["mental"] + 4.0 * contacts + 6.0 * seen_stalls + 8.0 * failures,
        "physical": BASE["physical"] + 0.1 * time_s,
        "temporal": BASE["temporal"] + 0.2 * (time_s - 30.0),
        "performance": BASE["performance"] + 5.0 * contacts + 15.0 * failures,
        "effort": BASE["effort"] + 0.15 * (time_s - 30.0) + 3.0 * contacts + 3.0 * seen_stalls,
        "frustration": BASE["frustration"] + 6.0 * contacts + 5.0 * seen_stalls + 12.0 * failures,
    }
    out = {}
    for s in TLX_SUBSCALES:
        value = raw[s] + offsets[s] + rng.normal(0.0, 5.0)
        out[s] = int(np.clip(5 * round(value / 5), 0, 100))
    return out


def person_offsets(rng: np.random.Generator) -> dict[str, float]:
    """How this person uses the scales (some rate everything high)."""
    general = rng.normal(0.0, 8.0)
    return {s: general + rng.normal(0.0, 5.0) for s in TLX_SUBSCALES}


def person_preference(rng: np.random.Generator) -> dict[str, float]:
    """How much this person weighs each subscale (the ranking their pairwise choices
    follow)."""
    preference = {s: rng.normal() for s in TLX_SUBSCALES}
    preference["mental"] += 1.0  # navigating by the screen is mentally demanding
    preference["effort"] += 0.5
    return preference


BLOCK_PREFERENCE_SD = 0.5
"""How far a block's weighing of the subscales moves from the person's (in units of the
spread between people): what a condition made salient, e.g. the force felt in HV, weighs
more after that block (assumption; the weights are asked after each block because they
differ between conditions, Hart and Staveland 1988)."""


def block_preference(preference: dict[str, float], rng: np.random.Generator) -> dict[str, float]:
    """The person's weighing of the subscales after one block."""
    return {s: v + rng.normal(0.0, BLOCK_PREFERENCE_SD) for s, v in preference.items()}


def pairwise_choices(
    study_seed: int, code: str, rng: np.random.Generator, preference: dict[str, float]
) -> list[str]:
    """The subscale picked from each of the 15 pairs, in the order the person saw them,
    following `preference` (`block_preference`) with some inconsistency."""
    chosen = []
    for left, right in pair_order(study_seed, code):
        diff = preference[left] - preference[right] + rng.normal(0.0, 0.5)
        chosen.append(left if diff > 0 else right)
    return chosen
