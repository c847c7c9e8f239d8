"""How well a person's own trials tell their traits: checked on people the emulator has
not seen, not taken from the emulator's slopes alone.

The linearised rule (`estimate.identifiable`) trusts the emulator's surface: where the
surface bends more than a quadratic can, or a feature is informative only in the few
trials where something happens (a backing-off), the slopes promise information the
trials do not hold. So the design's settings are split in `FOLDS`; an emulator fitted
to the other folds' trials estimates each held-out setting's traits from that
setting's own trials (the E-step of `estimate.GroupEstimator`, all traits free, under a
wide prior: the design box's centre, its half-width as SD), and the RMS error against
the setting's true traits is each trait's error for one person with `repeats` trials
per condition. On the LCCA task with 320 settings, the linearised rule promised the
haptic threshold to 0.43 of its prior SD in a group of 8, the held-out people to 0.6.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from study.analysis.participant_fit.emulator import MomentEmulator
from study.analysis.participant_fit.estimate import GroupEstimator
from study.analysis.participant_fit.observed import person_moments
from study.protocol.traits import TRAITS, GroupProfile

FOLDS = 4
"""Each held-out quarter is estimated by an emulator fitted to the other three."""
STEPS = 40
"""Levenberg-Marquardt steps per held-out person."""


def held_out_errors(
    x: np.ndarray,
    design: pd.DataFrame,
    measures: Sequence[str],
    features: Sequence[str],
    repeats: int,
    surface: MomentEmulator | None = None,
) -> np.ndarray:
    """(len(TRAITS),) RMS error of a held-out person's estimated traits (trait units), by
    emulators of `surface`'s degree and ridge penalties (default `MomentEmulator()`'s)."""
    surface = MomentEmulator() if surface is None else surface
    fold = np.arange(len(x)) % FOLDS
    low, high = x.min(axis=0), x.max(axis=0)
    centre, half = (low + high) / 2, (high - low) / 2
    wide = GroupProfile(**{t: (float(centre[j]), float(half[j])) for j, t in enumerate(TRAITS)})
    errors, truth = [], []
    for f in range(FOLDS):
        held = fold[design["setting"].to_numpy()] == f
        emulator = MomentEmulator(surface.degree, surface.alphas, mean_surface=False).fit(
            x, design[~held], measures, features
        )
        test = design[held].assign(
            participant=design.loc[held, "setting"].astype(str), group="design", order=""
        )
        people = person_moments(test, measures, emulator.features_)
        y = people[emulator.moments_].to_numpy(float)
        est = GroupEstimator(emulator, wide, list(range(len(TRAITS))), float(repeats))
        mu, sd = est.mu0, est.sd0
        theta, _, _ = est.posteriors(y, mu, sd, np.tile(mu, (len(y), 1)), STEPS)
        errors.append(theta)
        truth.append(x[people.index.astype(int)])
    err = np.concatenate(errors) - np.concatenate(truth)
    return np.sqrt((err**2).mean(axis=0))


def attach(emulator: MomentEmulator, x: np.ndarray, design: pd.DataFrame, repeats: int) -> None:
    """Set `emulator.held_out_error_` from its own design (every feature), and keep the
    design for `held_out_for`."""
    emulator.design_ = (x, design, repeats)
    emulator.held_out_error_ = held_out_errors(
        x, design, emulator.measures_, emulator.features_, repeats, emulator
    )


def held_out_trials(emulator: MomentEmulator) -> float | None:
    """Trials per condition of a held-out person (the design's repeats), or None."""
    return float(emulator.design_[2]) if hasattr(emulator, "design_") else None


def held_out_for(emulator: MomentEmulator, features: Sequence[str]) -> np.ndarray | None:
    """The held-out error with only `features` beside the measures (the ones a study's
    data have: an imported study without samples has none), or None without a design."""
    if not hasattr(emulator, "design_"):
        return None
    if list(features) == emulator.features_:
        return np.asarray(emulator.held_out_error_)
    x, design, repeats = emulator.design_
    return held_out_errors(x, design, emulator.measures_, features, repeats, emulator)
