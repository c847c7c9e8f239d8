"""The closed-form task the participant-effects tests share: an emulator of a closed form
of the traits, and a counterbalanced study drawn from it with effects injected.

Each test module states its own closed form (`Measures`: a trial's measures from the
person's traits at the trial and its condition, with its own trial noise); what it
builds on it, the emulator over the hand-set design box and the two-period crossover
of the hand-set profiles' people, is the same for all and lives here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from study.analysis.participant_fit.emulator import MomentEmulator, design_box, design_settings
from study.protocol.participant_effects import ParticipantEffect, apply_effects, session_place
from study.protocol.traits import ParticipantTraits, draw_traits

Measures = Callable[[ParticipantTraits, str, np.random.Generator], dict[str, float]]
"""A trial's measures from the person's traits at the trial and its condition."""


def closed_form_emulator(measures: Measures, names: Sequence[str]) -> MomentEmulator:
    """The emulator fitted to `measures` at 200 settings of the design box, one trial
    per condition each."""
    x = design_settings(200, 3, design_box())
    rng = np.random.default_rng(3)
    rows = []
    for k, row in enumerate(x):
        t = ParticipantTraits("design", *row)
        rows += [
            {"setting": k, "repeat": 0, "condition": c, **measures(t, c, rng)} for c in ("VO", "HV")
        ]
    return MomentEmulator().fit(x, pd.DataFrame(rows), list(names))


def closed_form_study(
    measures: Measures,
    injected: tuple[ParticipantEffect, ...],
    sizes: Mapping[str, int],
    trials_per_block: int,
    seed: int = 5,
) -> pd.DataFrame:
    """`sizes` people per group from the hand-set profiles, VO-first and HV-first in
    turn, `trials_per_block` trials per condition, each trial's traits with `injected`
    applied at its place in the session."""
    rng = np.random.default_rng(seed)
    rows = []
    for group, n in sizes.items():
        for i in range(n):
            person = draw_traits(group, rng)
            order = ["VO", "HV"] if i % 2 == 0 else ["HV", "VO"]
            for block, condition in enumerate(order):
                for r in range(trials_per_block):
                    place = session_place(order, block, r, trials_per_block)
                    rows.append(
                        {
                            "participant": f"{group[0].upper()}{i:02d}",
                            "group": group,
                            "order": f"{order[0]}-first",
                            "condition": condition,
                            "position": place.position,
                            "trial": r + 1,
                            **measures(apply_effects(person, injected, place), condition, rng),
                        }
                    )
    return pd.DataFrame(rows)
