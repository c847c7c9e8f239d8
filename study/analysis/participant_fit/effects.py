"""The loop on the people: find structure in the fitted model's residual, add the
participant effect that explains it, refit, and say how much better the model predicts
people it was not fitted to.

The families are `study.protocol.participant_effects` (practice, fatigue, carry-over
of the speed, carry-over of how hard one pushes, carry-overs on the forces alone and on
the time alone: multipliers on traits by a trial's place in the session), so that what
the fit adds, every simulation drawn from the model carries. Here:

- **structure** (`structure_tests`): two plain tests per measure on the trials' log
  measure (before an effect is added) or on it with the added effects taken out (after):
  a trend over trials (each person's within-condition slope over their trial position,
  a one-sample t-test of the people's slopes against 0) and an effect of condition order
  (each person's HV - VO mean, Welch's t-test between VO-first and HV-first people:
  `scipy.stats.ttest_ind(equal_var=False)`); Holm over all of them at `ALPHA`. A
  simulated person with no effect neither learns nor remembers the first condition, so
  neither test has anything to find in data the traits alone explain.
- **an effect's parameters** (`fit_effects`): least squares (`scipy.optimize.
  least_squares`, within each parameter's range) of every trial's log measures against
  the emulator's prediction for the person's fitted traits times the effects' multipliers
  at the trial's place, each measure in units of its trial noise, each group's level of
  the free traits the family acts on moving with the parameters (`TOUCHES`); alternated
  with the trait fit on the data with the effects taken out (each person's traits are
  then their plateau's), three rounds. The carry-over is fitted one direction at a time
  (`FREE`): in a two-period crossover only the difference between the condition orders
  tells a carry-over, and one free in both directions is a period effect too. The
  parameters' 95 % intervals: the same least squares on people resampled within group
  (each person's traits held, the groups' levels moving).
- **prediction error** (`prediction_error`): each quarter of the people (within group)
  held out in turn, the traits and the effects fitted to the other three quarters; in
  each cell of group x condition x condition order x trial position (the trial's place
  among the person's measured trials over both blocks; practice trials are not among
  the fit's trials), the held-out people's mean log measure minus the fitted model's
  mean there (the emulator's mean log measure over `DRAWS` people drawn from the fitted
  group distribution, the same draws for every cell, with the effects at the cell's
  place). The residuals of the four folds are pooled per cell before the mean (every
  person is held out once, so a cell's mean is over all of its people, not a fold's one
  to three); the RMS is over the cells and the measures. Beside it, the cells' noise
  floor (the RMS of their standard errors: the held-out people's own scatter, which no
  model removes) and the RMS of each measure alone; with `known` effects instead of
  fitted ones, the error a model that had the true effect reaches on the same people.
- **the loop** (`search`): while the structure tests flag something, the families not
  yet added are tried in turns (`shaped_candidates`), first those whose shape the
  flagged tests show. An effect of condition order on the time measures alone:
  `time_carry_over`, with practice and fatigue beside it (they make the second block
  slower or faster in either order); on the force measures alone: `force_carry_over`,
  with `gentle_carry_over` beside it; then `carry_over`, which moves both; then the
  rest. On both kinds of measure, or a trend alone, every family in one turn. In a
  turn, each family is fitted; the candidate is the one that lowers the trials' squared
  error most, but with no trend flagged the one-measure family the shape names stays
  the candidate unless another lowers the error below its own by the likelihood-ratio
  threshold (`Turn.preferred`; a flagged trend puts practice and fatigue in the first
  turn on equal terms). The candidate is taken if its drop passes a likelihood-ratio
  test (`LR_ALPHA`) and it lowers the held-out prediction error; else the next turn is
  tried. Then the tests run on the residual again. The verdict is `white` when nothing
  is flagged at the end, else `structure_remains` with what remains.

A person no trait setting reproduces (`checks.outliers`) is reported as
`unexplained_person`, never absorbed: no effect is fitted to one person.

The least squares are scipy's; the trait fit is the estimator's own (`estimate.py`),
without its bootstrap (the loop needs point estimates only, many times).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats
from scipy.optimize import least_squares

from study.analysis.participant_fit.checks import holm_flags
from study.analysis.participant_fit.emulator import MomentEmulator, floor, log_moment
from study.analysis.participant_fit.estimate import DRAWS, HIGH, LOW, GroupEstimator, GroupFit
from study.analysis.participant_fit.observed import person_moments
from study.protocol.participant_effects import (
    BOUNDS,
    FAMILIES,
    ParticipantEffect,
    TrialPlace,
)
from study.protocol.tasks import measure_named
from study.protocol.traits import PROFILES, TRAITS
from teleop_core.progress import Progress, no_progress

ALPHA = 0.05
"""Family-wise error rate of the structure tests (Holm)."""
TRENDS = ("practice", "fatigue")
SHAPED: dict[str, tuple[tuple[str, ...], ...]] = {
    "time": (("time_carry_over", *TRENDS), ("carry_over",)),
    "force": (("force_carry_over", "gentle_carry_over"), ("carry_over",)),
}
"""The turns tried first when the condition order's effect is flagged on the time
measures alone (`time`) or on the force measures alone (`force`): the families that act
on that measure, the one that moves it alone named first (`Turn.preferred`), then the
carry-over that moves the time and the forces together (the rest after). The one
fitting the trials best is not simply the one to take: a carry-over that moves both
measures also takes up the order difference in the forces that people show without an
effect, so it can fit a time-only carry-over's trials better than the time-only family
does. Practice and fatigue act on the speed and make the second block faster or slower
in either order, an order effect on the time whether or not the trend test sees it
(with few trials per condition it may not), so they are tried beside the time-only
carry-over, which they displace only by a clear margin: with few trials per block a
fatigue fits a carry-over's trials about as well. On the forces, the gentle carry-over
(how hard one pushes) beside the forces-only one, on the same terms. Flagged on both
kinds of measure, on another kind, or not at all (a trend alone), every family competes
in one turn."""
LR_ALPHA = 0.01
"""A family is added when its likelihood-ratio test (the drop of the trials' squared
standardised error against chi-square) passes at this level and it lowers the held-out
prediction error."""
ROUNDS = 3
"""Alternations of the trait fit and the effects' least squares."""
FOLDS = 4
BOOTSTRAP = 200
"""People resamplings for the effects' parameter intervals."""
FREE: dict[str, tuple[tuple[str, ...], ...]] = {
    "practice": (FAMILIES["practice"],),
    "fatigue": (FAMILIES["fatigue"],),
    "carry_over": (("vo_after_hv",), ("hv_after_vo",)),
    "gentle_carry_over": (("gentler_vo_after_hv",), ("gentler_hv_after_vo",)),
    "force_carry_over": (("softer_vo_after_hv",), ("softer_hv_after_vo",)),
    "time_carry_over": (("slower_vo_after_hv",), ("slower_hv_after_vo",)),
}
"""The parameters the least squares moves together, per family, and the alternatives
tried. The carry-over moves one direction at a time, the other held at 0: in a
two-period crossover the data tell only the difference between the two condition
orders, and a carry-over free in both directions reproduces a period effect exactly
(both shares equal), so it would take a practice effect's common speed-up between the
blocks for itself. One direction cannot: it moves one condition's second block only,
which is what the orders' difference is."""
FIT_BOUNDS = {**BOUNDS, "rate": (0.0, BOUNDS["rate"][1])}
"""The parameters' ranges in the fit: `BOUNDS`, but the fatigue's rate only slows (a
negative rate, a session-long speed-up, is learning, which is practice's to name: with
three trials per condition the two shapes are close, and a fitted negative fatigue
took the place of an injected practice effect)."""
START = {
    "slowing": 0.3,
    "decay_trials": 2.0,
    "rate": 0.01,
    "vo_after_hv": 0.0,
    "hv_after_vo": 0.0,
    "gentler_vo_after_hv": 0.0,
    "gentler_hv_after_vo": 0.0,
    "softer_vo_after_hv": 0.0,
    "softer_hv_after_vo": 0.0,
    "slower_vo_after_hv": 0.0,
    "slower_hv_after_vo": 0.0,
}
DEFINITION = (
    "each quarter of the people (dealt within group) held out in turn and the model "
    "(traits and participant effects) fitted to the other three; every held-out trial's "
    "log measure minus the fitted model's mean log measure in its cell of group x "
    "condition x condition order x trial position (the trial's place among the person's "
    "measured trials over both blocks, practice trials not among them), the model's "
    f"mean being the emulator's over {DRAWS} people drawn from the fitted group "
    "distribution with the effects at the cell's place; the residuals of all four folds "
    "pooled per cell (every person is held out once) and averaged there; the RMS of "
    "these cell means over every cell and measure observed, each weighted alike; log units"
)


# --- the trials as arrays -------------------------------------------------------------


@dataclass
class TrialArrays:
    """The trials in the shape the effects' least squares needs."""

    frame: pd.DataFrame
    y: np.ndarray
    """(trials, measures) log measures."""
    columns: np.ndarray
    """(trials, measures) index of the trial's condition's measure moment."""
    places: list[TrialPlace]
    groups: np.ndarray
    people: np.ndarray


def trial_arrays(trials: pd.DataFrame, emulator: MomentEmulator) -> TrialArrays:
    measures = emulator.measures_
    names = emulator.moments_
    frame = trials.reset_index(drop=True)
    y = np.column_stack([log_moment(frame[m]) for m in measures])
    columns = np.array([[names.index(f"{c}:{m}") for m in measures] for c in frame["condition"]])
    first = frame["order"].str.split("-").str[0].to_numpy()
    places = [
        TrialPlace(int(p), 0 if c == f else 1, c, f)
        for p, c, f in zip(frame["position"], frame["condition"], first, strict=True)
    ]
    return TrialArrays(
        frame, y, columns, places, frame["group"].to_numpy(), frame["participant"].to_numpy()
    )


def factor_matrix(
    effects: Sequence[ParticipantEffect],
    places: Sequence[TrialPlace],
    groups: Sequence[str] | np.ndarray,
) -> np.ndarray:
    """(trials, len(TRAITS)) the effects' multiplier on each trait at each trial, by
    `ParticipantEffect.factors` once per distinct (place, group)."""
    out = np.ones((len(places), len(TRAITS)))
    if not effects:
        return out
    cache: dict[tuple[TrialPlace, str], np.ndarray] = {}
    for i, key in enumerate(zip(places, groups, strict=True)):
        if key not in cache:
            row = np.ones(len(TRAITS))
            for effect in effects:
                if effect.applies_to(key[1]):
                    for trait, f in effect.factors(key[0]).items():
                        row[TRAITS.index(trait)] *= f
            cache[key] = row
        out[i] = cache[key]
    return out


def _predicted(
    emulator: MomentEmulator, theta: np.ndarray, factors: np.ndarray, columns: np.ndarray
) -> np.ndarray:
    """(trials, columns) the emulator's log moments of each trial's traits times the
    effects' factors, at each trial's `columns`."""
    f = emulator.log_moments(np.clip(theta * factors, LOW, HIGH))
    return np.take_along_axis(f, columns, axis=1)


def without_effects(
    trials: pd.DataFrame,
    emulator: MomentEmulator,
    effects: Sequence[ParticipantEffect],
    theta: np.ndarray,
) -> pd.DataFrame:
    """The trials with the effects taken out of every measure and feature the emulator
    has: each divided by exp(f(traits x factors) - f(traits)) at the trial's place
    (`theta`: (trials, len(TRAITS)) each trial's person's traits)."""
    if not effects:
        return trials
    arrays = trial_arrays(trials, emulator)
    factors = factor_matrix(effects, arrays.places, arrays.groups)
    shift = emulator.log_moments(np.clip(theta * factors, LOW, HIGH)) - emulator.log_moments(theta)
    out = arrays.frame.copy()
    names = emulator.moments_
    for column in [*emulator.measures_, *emulator.features_]:
        idx = np.array([names.index(f"{c}:{column}") for c in out["condition"]])
        values = out[column].to_numpy(float)
        low = floor(column, emulator.measures_)
        out[column] = np.where(
            np.isfinite(values),
            np.maximum(values, low) * np.exp(-shift[np.arange(len(out)), idx]),
            values,
        )
    return out


# --- structure ------------------------------------------------------------------------


def _slopes(frame: pd.DataFrame, y: np.ndarray) -> np.ndarray:
    """Each person's slope of `y` over position within condition (units per trial)."""
    f = frame.assign(y=y, x=frame["position"].astype(float))
    keys = ["participant", "condition"]
    f["dx"] = f["x"] - f.groupby(keys)["x"].transform("mean")
    f["dy"] = f["y"] - f.groupby(keys)["y"].transform("mean")
    sums = f.assign(xy=f["dx"] * f["dy"], xx=f["dx"] ** 2).groupby("participant")[["xy", "xx"]]
    s = sums.sum()
    return (s["xy"] / s["xx"].where(s["xx"] > 0)).dropna().to_numpy()


def _order_differences(frame: pd.DataFrame, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each person's HV - VO mean of `y`: VO-first people's, HV-first people's."""
    wide = frame.assign(y=y).groupby(["participant", "order", "condition"])["y"].mean().unstack()
    d = (wide["HV"] - wide["VO"]).dropna().reset_index()
    return (
        d.loc[d["order"] == "VO-first", 0].to_numpy(),
        d.loc[d["order"] == "HV-first", 0].to_numpy(),
    )


def structure_tests(
    frame: pd.DataFrame, y: np.ndarray, measures: Sequence[str]
) -> list[dict[str, Any]]:
    """The trend and order tests of each measure (columns of `y`, log scale), Holm."""
    rows: list[dict[str, Any]] = []
    for j, m in enumerate(measures):
        s = _slopes(frame, y[:, j])
        if len(s) >= 3 and np.ptp(s) > 0:
            rows.append(
                {
                    "check": "trend",
                    "measure": m,
                    "pct_per_trial": 100 * float(np.expm1(s.mean())),
                    "participants": len(s),
                    "p": float(stats.ttest_1samp(s, 0.0).pvalue),
                }
            )
        a, b = _order_differences(frame, y[:, j])
        if len(a) >= 2 and len(b) >= 2:
            p = float(stats.ttest_ind(a, b, equal_var=False).pvalue)
            rows.append(
                {
                    "check": "order",
                    "measure": m,
                    "vo_first_minus_hv_first_pct": 100 * float(np.expm1(a.mean() - b.mean())),
                    "participants": len(a) + len(b),
                    "p": p if np.isfinite(p) else 1.0,
                }
            )
    if rows:
        holm_flags(rows, ALPHA)
    return rows


def describe(rows: Sequence[dict[str, Any]]) -> list[str]:
    """What the flagged structure tests found, one phrase each."""
    out = []
    for r in rows:
        if r["flagged"] and r["check"] == "trend":
            out.append(
                f"a trend over trials in {r['measure']} ({r['pct_per_trial']:+.1f} %/trial, "
                f"p_holm = {r['p_holm']:.2g})"
            )
        elif r["flagged"]:
            out.append(
                f"an effect of condition order on {r['measure']} (VO-first minus "
                f"HV-first {r['vo_first_minus_hv_first_pct']:+.1f} %, "
                f"p_holm = {r['p_holm']:.2g})"
            )
    return out


# --- fitting --------------------------------------------------------------------------


@dataclass
class PeopleFit:
    """Point estimates of the traits (per group and per person) and of the effects."""

    groups: dict[str, GroupFit]
    theta: dict[str, np.ndarray]
    """participant -> (len(TRAITS),) their fitted traits."""
    effects: list[ParticipantEffect] = field(default_factory=list)
    estimators: dict[str, GroupEstimator] = field(default_factory=dict)


def fit_traits(
    trials: pd.DataFrame, emulator: MomentEmulator, free: list[int], weak: list[int], seed: int
) -> PeopleFit:
    """Each group's trait distribution and each person's traits (no bootstrap)."""

    people = person_moments(trials, emulator.measures_, emulator.features_)
    out = PeopleFit({}, {})
    for group, g in people.groupby("group", sort=False):
        est = GroupEstimator(emulator, PROFILES[group], free, float(g["k"].mean()), seed, weak)
        best = est.fit(g[emulator.moments_].to_numpy(float))
        out.groups[group], out.estimators[group] = best, est
        out.theta.update(dict(zip(g.index, best.people, strict=True)))
    return out


Spec = tuple[tuple[str, tuple[str, ...]], ...]
"""Families with the parameters the least squares moves (the others held at 0)."""


def _specs(families: Sequence[str]) -> list[Spec]:
    """Every way to fit `families`: one per combination of their `FREE` alternatives."""
    out: list[Spec] = [()]
    for family in families:
        out = [(*spec, (family, names)) for spec in out for names in FREE[family]]
    return out


def _effects(
    spec: Spec,
    x: np.ndarray,
    groups: tuple[str, ...],
    intervals: dict[str, tuple[float, float]] | None = None,
) -> list[ParticipantEffect]:
    out, k = [], 0
    for family, free in spec:
        params = {n: 0.0 for n in FAMILIES[family]}
        params.update({n: float(np.clip(x[k + i], *FIT_BOUNDS[n])) for i, n in enumerate(free)})
        ivs = {n: intervals[n] for n in free if intervals and n in intervals}
        # a parameter held at 0 has no spread to report: its interval is the point
        ivs.update({n: (0.0, 0.0) for n in FAMILIES[family] if n not in free and intervals})
        out.append(ParticipantEffect(family, params, groups, ivs))
        k += len(free)
    return out


TOUCHES: dict[str, tuple[str, ...]] = {
    "practice": ("preferred_speed_m_s",),
    "fatigue": ("preferred_speed_m_s", "reaction_s"),
    "carry_over": ("preferred_speed_m_s", "visual_stall_s"),
    "gentle_carry_over": ("caution", "comfort_torque_n_m"),
    "force_carry_over": ("steering_error_rad", "preferred_speed_m_s"),
    "time_carry_over": ("preferred_speed_m_s", "visual_stall_s", "haptic_threshold_n_m"),
}
"""The traits each family's multipliers act on (`ParticipantEffect.factors`)."""
LEVEL = 0.5
"""How far (log) a group's level of such a trait may move in the effects' least squares."""


def _least_squares(
    arrays: TrialArrays,
    emulator: MomentEmulator,
    theta: np.ndarray,
    spec: Spec,
    groups: tuple[str, ...],
    start: np.ndarray,
    weights: np.ndarray,
    free: Sequence[int] = (),
) -> tuple[np.ndarray, float]:
    """The free parameters of `spec` and the trials' squared standardised error there.

    With `free` (the fitted traits), each group's level of every free trait the
    families act on moves with them (a log multiplier, not returned): a practice effect
    and a slower person are the same slowing in a session's mean, so the effect's
    parameters against traits held where they were fitted without it come out too
    small, and alternating with the trait fit closes the gap only slowly."""
    names = [n for _, free_names in spec for n in free_names]
    touched = sorted({TRAITS.index(t) for family, _ in spec for t in TOUCHES[family]} & set(free))
    g_index = np.searchsorted(np.array(groups), arrays.groups)
    n_level = len(groups) * len(touched)
    # a decay longer than the session's measured trials is a level, not a decay: the
    # traits' own (a large slowing decaying over many sessions' length, with every
    # group's speed raised to match, fits the trials as well as the true effect and
    # predicts held-out people far worse)
    span = float(max(p.position for p in arrays.places) + 1)
    bounds = {**FIT_BOUNDS, "decay_trials": (FIT_BOUNDS["decay_trials"][0], max(span, 1.0))}
    low = np.array([bounds[n][0] for n in names] + [-LEVEL] * n_level)
    high = np.array([bounds[n][1] for n in names] + [LEVEL] * n_level)
    noise = np.sqrt(emulator.within_var_[arrays.columns])
    k = len(names)

    def residuals(x: np.ndarray) -> np.ndarray:
        factors = factor_matrix(_effects(spec, x[:k], groups), arrays.places, arrays.groups)
        if n_level:
            level = np.exp(x[k:].reshape(len(groups), len(touched)))
            factors[:, touched] *= level[g_index]
        r = (arrays.y - _predicted(emulator, theta, factors, arrays.columns)) / noise
        return (r * weights[:, None]).ravel()

    x0 = np.concatenate([start[:k], np.zeros(n_level)])
    found = least_squares(residuals, np.clip(x0, low, high), bounds=(low, high), x_scale="jac")
    return found.x[:k], 2.0 * float(found.cost)


def fit_effects(
    trials: pd.DataFrame,
    emulator: MomentEmulator,
    families: Sequence[str],
    free: list[int],
    weak: list[int],
    seed: int,
    bootstrap: int = 0,
) -> PeopleFit:
    """The traits and the `families`' parameters, alternated (`ROUNDS`); with
    `bootstrap`, the parameters' 95 % intervals over people resampled within group."""
    groups = tuple(sorted(trials["group"].unique()))
    fit = fit_traits(trials, emulator, free, weak, seed)
    if not families:
        return fit
    arrays = trial_arrays(trials, emulator)
    ones = np.ones(len(arrays.y))
    theta = np.array([fit.theta[p] for p in arrays.people])
    # each way to fit the families (the carry-over's one direction or the other) from
    # the traits fitted without effects; the one that fits the trials best is kept
    tried = []
    for spec in _specs(families):
        start = np.array([START[n] for _, names in spec for n in names])
        x, cost = _least_squares(arrays, emulator, theta, spec, groups, start, ones, free)
        tried.append((cost, spec, x))
    _, spec, x = min(tried, key=lambda t: t[0])
    for _ in range(ROUNDS):
        effects = _effects(spec, x, groups)
        adjusted = without_effects(trials, emulator, effects, theta)
        fit = fit_traits(adjusted, emulator, free, weak, seed)
        theta = np.array([fit.theta[p] for p in arrays.people])
        x, _ = _least_squares(arrays, emulator, theta, spec, groups, x, ones, free)
    intervals = None
    if bootstrap:
        rng = np.random.default_rng([seed, 0xEFFE])
        codes = trials.drop_duplicates("participant")[["participant", "group"]]
        draws = []
        for _ in range(bootstrap):
            # people resampled within group: each trial weighted by its person's count
            picked = codes.groupby("group")["participant"].transform(
                lambda s: rng.choice(s.to_numpy(), len(s))
            )
            counts = picked.value_counts()
            w = np.sqrt(np.array([counts.get(p, 0) for p in arrays.people], dtype=float))
            draws.append(_least_squares(arrays, emulator, theta, spec, groups, x, w, free)[0])
        draws_arr = np.array(draws)
        names = [n for _, free_names in spec for n in free_names]
        intervals = {
            n: tuple(np.percentile(draws_arr[:, i], [2.5, 97.5]).tolist())
            for i, n in enumerate(names)
        }
    fit.effects = _effects(spec, x, groups, intervals)
    return fit


def fit_known(
    trials: pd.DataFrame,
    emulator: MomentEmulator,
    known: Sequence[ParticipantEffect],
    free: list[int],
    weak: list[int],
    seed: int,
) -> PeopleFit:
    """The traits fitted to the trials with `known` effects taken out (alternated
    `ROUNDS` times, as `fit_effects` does), the effects held as given."""
    people = trial_arrays(trials, emulator).people
    fit = fit_traits(trials, emulator, free, weak, seed)
    for _ in range(ROUNDS):
        theta = np.array([fit.theta[p] for p in people])
        adjusted = without_effects(trials, emulator, known, theta)
        fit = fit_traits(adjusted, emulator, free, weak, seed)
    fit.effects = list(known)
    return fit


def residual_structure(
    trials: pd.DataFrame, emulator: MomentEmulator, fit: PeopleFit
) -> list[dict[str, Any]]:
    """The structure tests on the trials with the fit's effects taken out."""
    arrays = trial_arrays(trials, emulator)
    y = arrays.y
    if fit.effects:
        theta = np.array([fit.theta[p] for p in arrays.people])
        factors = factor_matrix(fit.effects, arrays.places, arrays.groups)
        y = y - (
            _predicted(emulator, theta, factors, arrays.columns)
            - _predicted(emulator, theta, np.ones_like(factors), arrays.columns)
        )
    return structure_tests(arrays.frame, y, emulator.measures_)


def _sse(trials: pd.DataFrame, emulator: MomentEmulator, fit: PeopleFit) -> float:
    arrays = trial_arrays(trials, emulator)
    theta = np.array([fit.theta[p] for p in arrays.people])
    factors = factor_matrix(fit.effects, arrays.places, arrays.groups)
    r = (arrays.y - _predicted(emulator, theta, factors, arrays.columns)) / np.sqrt(
        emulator.within_var_[arrays.columns]
    )
    return float((r**2).sum())


# --- held-out prediction ----------------------------------------------------------------


def cell_means(trials: pd.DataFrame, measures: Sequence[str]) -> pd.DataFrame:
    """Mean log measure per group x condition x order x position."""
    logged = trials.assign(**{m: log_moment(trials[m]) for m in measures})
    return logged.groupby(["group", "condition", "order", "position"])[list(measures)].mean()


def predicted_cells(cells: pd.Index, emulator: MomentEmulator, fit: PeopleFit) -> np.ndarray:
    """(cells, measures) the fitted model's mean log measure in each cell."""
    names, measures = emulator.moments_, emulator.measures_
    out = np.zeros((len(cells), len(measures)))
    for i, (group, condition, order, position) in enumerate(cells):
        est, best = fit.estimators[group], fit.groups[group]
        draws = est.draws(best.mean, best.sd)
        first = order.split("-")[0]
        place = TrialPlace(int(position), 0 if condition == first else 1, condition, first)
        factors = factor_matrix(fit.effects, [place], [group])
        f = emulator.log_moments(np.clip(draws * factors, LOW, HIGH))
        out[i] = f[:, [names.index(f"{condition}:{m}") for m in measures]].mean(axis=0)
    return out


def folds(trials: pd.DataFrame, seed: int, n: int = FOLDS) -> dict[str, int]:
    """participant -> fold, dealt in turn within each group after a seeded shuffle."""
    rng = np.random.default_rng([seed, 0xF01D])
    out: dict[str, int] = {}
    for _, g in trials.drop_duplicates("participant").groupby("group", sort=True):
        codes = g["participant"].to_numpy()
        for k, code in enumerate(codes[rng.permutation(len(codes))]):
            out[code] = k % n
    return out


@dataclass
class HeldOut:
    """The held-out prediction error and the part of it the cells' own noise explains."""

    error: float
    """RMS over cells and measures of the held-out people's mean log measure minus the
    model's (each person predicted by the fit without their quarter)."""
    noise_floor: float
    """RMS of the cells' standard errors: what a model that knew every cell's true
    mean would still show, from the held-out people's own scatter."""
    by_measure: dict[str, float] = field(default_factory=dict)
    """The same RMS over the cells of each measure alone."""
    floor_by_measure: dict[str, float] = field(default_factory=dict)
    """The noise floor over the cells of each measure alone."""
    cells: int = 0
    """The (cell, measure) means the RMS is over."""

    @property
    def excess(self) -> float:
        """The error beyond the noise floor: sqrt(error^2 - floor^2), 0 when below."""
        return float(np.sqrt(max(self.error**2 - self.noise_floor**2, 0.0)))


def prediction_error(
    trials: pd.DataFrame,
    emulator: MomentEmulator,
    families: Sequence[str],
    free: list[int],
    weak: list[int],
    seed: int,
    known: Sequence[ParticipantEffect] = (),
) -> HeldOut:
    """The held-out prediction error (`DEFINITION`): every person is held out once (in
    their quarter), their trials set against the model fitted to the other quarters in
    their cell; a cell's error is the mean over its held-out trials. With `known`, the
    model's effects are those (not fitted; `families` unused): what a model that had
    the true effect would reach on these people, the bound a fitted one is set against."""
    fold = trials["participant"].map(folds(trials, seed))
    keys = ["group", "condition", "order", "position"]
    parts = []
    for k in range(FOLDS):
        train, test = trials[fold != k], trials[fold == k]
        if test.empty:
            continue
        if known:
            fit = fit_known(train, emulator, known, free, weak, seed)
        else:
            fit = fit_effects(train, emulator, families, free, weak, seed)
        test = test[test["group"].isin(list(fit.groups))]
        logged = test.assign(**{m: log_moment(test[m]) for m in emulator.measures_})
        cells = pd.MultiIndex.from_frame(logged[keys].drop_duplicates())
        pred = pd.DataFrame(
            predicted_cells(cells, emulator, fit), index=cells, columns=emulator.measures_
        )
        at = pred.loc[pd.MultiIndex.from_frame(logged[keys])].to_numpy()
        diff = logged[emulator.measures_].to_numpy(float) - at
        parts.append(
            pd.concat(
                [
                    logged[keys].reset_index(drop=True),
                    pd.DataFrame(diff, columns=emulator.measures_),
                ],
                axis=1,
            )
        )
    d = pd.concat(parts).groupby(keys)[emulator.measures_]
    mean, se = d.mean().to_numpy(), (d.std(ddof=1) / np.sqrt(d.count())).to_numpy()
    ok = np.isfinite(mean)
    return HeldOut(
        float(np.sqrt(np.mean(mean[ok] ** 2))),
        float(np.sqrt(np.nanmean(se[np.isfinite(se)] ** 2))),
        {
            m: float(np.sqrt(np.mean(mean[ok[:, j], j] ** 2)))
            for j, m in enumerate(emulator.measures_)
            if ok[:, j].any()
        },
        {
            m: float(np.sqrt(np.nanmean(se[np.isfinite(se[:, j]), j] ** 2)))
            for j, m in enumerate(emulator.measures_)
            if np.isfinite(se[:, j]).any()
        },
        int(ok.sum()),
    )


# --- the loop -------------------------------------------------------------------------


@dataclass
class EffectSearch:
    """What the loop added and found."""

    effects: list[ParticipantEffect]
    fit: PeopleFit
    before: list[dict[str, Any]]
    """The structure tests on the trials as they are."""
    after: list[dict[str, Any]]
    """The same with the added effects taken out."""
    error_before: HeldOut
    error_after: HeldOut
    tried: list[dict[str, Any]]
    adjusted: pd.DataFrame
    """The trials with the added effects taken out (what the traits are fitted to)."""

    @property
    def verdict(self) -> str:
        return "structure_remains" if any(r["flagged"] for r in self.after) else "white"

    def line(self) -> str:
        """The one printed line: the effect(s) added and the error before and after."""
        if self.effects:
            added = "; ".join(
                f"{e.family} (" + ", ".join(f"{n} {v:.3g}" for n, v in e.parameters.items()) + ")"
                for e in self.effects
            )
            b, a = self.error_before, self.error_after
            noise = (
                f"beyond the cells' noise {b.excess:.4f} -> {a.excess:.4f}"
                if b.excess > 0 or a.excess > 0
                else "within the cells' own noise before and after"
            )
            return (
                f"participant effects: added {added}; held-out prediction error "
                f"{b.error:.4f} -> {a.error:.4f} (log units, {self.reduction():.0%} lower; "
                f"{noise}); verdict {self.verdict}"
            )
        found = describe(self.before)
        if not found:
            return (
                "participant effects: none added, the residual shows no structure (verdict white)"
            )
        return (
            "participant effects: none added (no family lowered the held-out prediction "
            f"error); structure remains: {'; '.join(found)}"
        )

    def reduction(self) -> float:
        """The held-out error's relative drop from before to after."""
        return 1.0 - self.error_after.error / self.error_before.error

    def to_dict(self, unexplained: Sequence[str] = ()) -> dict[str, Any]:
        remains = describe(self.after)
        return {
            "participant_effects": [e.to_dict() for e in self.effects],
            "prediction_error": {
                "before": self.error_before.error,
                "after": self.error_after.error,
                "definition": DEFINITION,
                "noise_floor": {
                    "before": self.error_before.noise_floor,
                    "after": self.error_after.noise_floor,
                },
                "beyond_noise": {
                    "before": self.error_before.excess,
                    "after": self.error_after.excess,
                },
                "by_measure": {
                    "before": self.error_before.by_measure,
                    "after": self.error_after.by_measure,
                    "noise_floor": self.error_before.floor_by_measure,
                },
                "cells": self.error_before.cells,
                "noise_note": "noise_floor: the RMS of the cells' standard errors (the held-out "
                "people's own scatter, which no model removes); beyond_noise: "
                "sqrt(error^2 - noise_floor^2); by_measure: the same RMS over the cells of "
                "each measure alone; cells: the (cell, measure) means the RMS is over",
            },
            "verdict": self.verdict,
            "remains": remains,
            "unexplained_people": {
                "family": "unexplained_person",
                "participants": list(unexplained),
                "note": "people no trait setting reproduces (the outlier rule of `lacks`): "
                "reported, never absorbed into the model",
            },
            "effects_search": {
                "structure_before": self.before,
                "structure_after": self.after,
                "tried": self.tried,
                "rule": f"structure tests Holm at {ALPHA}; the families whose shape the "
                "flagged tests show are tried first (an order effect on the time alone: "
                "time_carry_over, with practice and fatigue beside it; on the forces "
                "alone: force_carry_over, with gentle_carry_over beside it; then "
                "carry_over), then the others; in a turn the family fitting the trials "
                "best, but without a flagged trend the one the shape names unless another "
                "fits better by the likelihood-ratio threshold; it is added when its "
                f"likelihood-ratio test passes at {LR_ALPHA} and it lowers the held-out "
                "prediction error",
            },
            "effects_line": self.line(),
        }


def measure_kind(measure: str) -> str | None:
    """`time` for a measure in seconds, `force` for one in newtons (its `Measure.unit`,
    else the unit its name ends in), None for any other."""
    declared = measure_named(measure)
    unit = declared.unit if declared is not None else measure.rsplit("_", 1)[-1]
    return {"s": "time", "n": "force"}.get(unit.lower())


@dataclass(frozen=True)
class Turn:
    """Families fitted side by side in one turn of the loop."""

    families: tuple[str, ...]
    preferred: str | None = None
    """The family the flagged tests' shape names: another of the turn is the candidate
    only when it lowers the trials' squared standardised error below this one's by the
    likelihood-ratio test's threshold (`LR_ALPHA`, its parameters)."""


def shaped_candidates(rows: Sequence[dict[str, Any]], added: Sequence[str]) -> list[Turn]:
    """The families the loop tries, turn by turn, those not yet `added` (`SHAPED`):
    first those whose shape the flagged structure tests (`rows`) show, then the others."""
    flagged = [r for r in rows if r["flagged"]]
    kinds = {measure_kind(r["measure"]) for r in flagged if r["check"] == "order"}
    one = next(iter(kinds)) if len(kinds) == 1 else None
    trend = any(r["check"] == "trend" for r in flagged)
    turns = [Turn(t, None if trend else t[0]) for t in SHAPED.get(one or "", ())]
    if turns and trend:
        turns[0] = Turn((*turns[0].families, *(f for f in TRENDS if f not in turns[0].families)))
    out, seen = [], set(added)
    for turn in [*turns, Turn(tuple(FAMILIES))]:
        fresh = tuple(f for f in turn.families if f not in seen)
        seen.update(fresh)
        if fresh:
            out.append(Turn(fresh, turn.preferred if turn.preferred in fresh else None))
    return out


def _candidate(scored: Sequence[tuple[float, str]], preferred: str | None) -> tuple[float, str]:
    """The turn's (squared error, family): the lowest, unless the `preferred` family's
    is within the likelihood-ratio threshold of it."""
    best = min(scored)
    if preferred is None:
        return best
    mine = next(s for s in scored if s[1] == preferred)
    margin = stats.chi2.ppf(1 - LR_ALPHA, len(FAMILIES[best[1]]))
    return mine if mine[0] - best[0] < margin else best


def search(
    trials: pd.DataFrame,
    emulator: MomentEmulator,
    free: list[int],
    weak: list[int],
    seed: int,
    bootstrap: int = BOOTSTRAP,
    progress: Progress = no_progress,
) -> EffectSearch:
    """The loop: test, add the family that explains the structure, refit, test again."""
    arrays = trial_arrays(trials, emulator)
    before = structure_tests(arrays.frame, arrays.y, emulator.measures_)
    added: list[str] = []
    fit = fit_traits(trials, emulator, free, weak, seed)
    after, tried = before, []
    error_before = error_now = prediction_error(trials, emulator, [], free, weak, seed)
    sse_now = _sse(trials, emulator, fit)
    steps = 0
    while any(r["flagged"] for r in after) and len(added) < len(FAMILIES):
        taken = None
        for turn in shaped_candidates(after, added):
            scored = []
            for family in turn.families:
                progress("effects", steps, len(FAMILIES) + 1)
                steps += 1
                trial_fit = fit_effects(trials, emulator, [*added, family], free, weak, seed)
                scored.append((_sse(trials, emulator, trial_fit), family))
            sse, best = _candidate(scored, turn.preferred)
            error = prediction_error(trials, emulator, [*added, best], free, weak, seed)
            # the drop in squared standardised error, against chi-square with the new
            # parameters' degrees of freedom (a likelihood-ratio test of the family)
            lr = sse_now - sse
            tried.append(
                {
                    "family": best,
                    "in_sample": {f: round(s, 3) for s, f in scored},
                    "likelihood_ratio": lr,
                    "held_out_error": error.error,
                    "held_out_error_without": error_now.error,
                }
            )
            significant = lr >= stats.chi2.ppf(1 - LR_ALPHA, len(FAMILIES[best]))
            if significant and error.error < error_now.error:
                taken = best, error, sse
                break
        if taken is None:
            break
        best, error_now, sse_now = taken
        added.append(best)
        fit = fit_effects(trials, emulator, added, free, weak, seed, bootstrap)
        after = residual_structure(trials, emulator, fit)
    progress("effects", len(FAMILIES) + 1, len(FAMILIES) + 1)
    adjusted = trials
    if fit.effects:
        people = trial_arrays(trials, emulator).people
        theta = np.array([fit.theta[p] for p in people])
        adjusted = without_effects(trials, emulator, fit.effects, theta)
    return EffectSearch(
        fit.effects,
        fit,
        before,
        after,
        error_before,
        error_now if fit.effects else error_before,
        tried,
        adjusted,
    )
