"""The fit's summaries: observed vs simulated per group, condition and measure, and the
effects `study power --participants` takes from the people simulated from the fit."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from study.analysis.participant_fit.observed import bootstrap_means
from study.protocol.traits import TRAITS

TRAIT_COLUMN = "trait:"
"""Prefix of the columns that carry a simulated person's traits (`fit.simulate_people`)."""
TRAIT_COLUMNS = [f"{TRAIT_COLUMN}{t}" for t in TRAITS]
"""Those columns, in the order of `TRAITS` (the emulator's)."""

DIFFERENCE = "HV-VO"
"""The condition label of each person's HV - VO difference: the analysis's sign
(`study analyze`, `study power`), so a positive value is more in HV."""
CONDITIONS = ("VO", "HV", DIFFERENCE)
"""The summaries' conditions: each condition's mean, then the difference."""

Discrepancy = dict[tuple[str, str, str], tuple[float, float, int]]
"""(group, measure, condition) -> the emulator's discrepancy: its mean, SE and people."""


def condition_values(
    frame: pd.DataFrame, measures: Sequence[str], groups: Sequence[str]
) -> Iterator[tuple[str, str, str, pd.Series]]:
    """(group, measure, condition, values) per group, measure and condition (VO, HV and
    each person's HV - VO, `DIFFERENCE`): the people's means of the measure, people with
    both conditions only."""
    means = frame.groupby(["group", "participant", "condition"])[list(measures)].mean()
    for group in groups:
        g = means.xs(group, level="group")
        for m in measures:
            wide = g[m].unstack().dropna()
            yield group, m, "VO", wide["VO"]
            yield group, m, "HV", wide["HV"]
            yield group, m, DIFFERENCE, wide["HV"] - wide["VO"]


def emulator_discrepancy(
    simulated: pd.DataFrame,
    measures: Sequence[str],
    groups: Sequence[str],
    emulator: Any,
) -> Discrepancy:
    """What the simulator gives beyond the emulator for the people simulated from the fit:
    per group, measure and condition (and HV - VO), the mean over those people of their
    mean measure minus the emulator's mean at their own traits (the `TRAIT_COLUMNS`
    columns), its standard error and the number of people (those with both conditions).

    Each person's own traits stand as a control variate: their spread between people,
    which the emulator follows, drops out of the difference, so its SE is the trials'
    noise and the emulator's misfit only, far below that of the simulated people's mean
    itself. The mean surface is a smooth fit to a finite design; where it bends off the
    simulator (a capped time, a skewed force), this is how far, measured where the
    fitted people lie."""
    keys = ["group", "participant"]
    people = simulated.groupby(keys)[TRAIT_COLUMNS].first()
    means = simulated.groupby([*keys, "condition"])[list(measures)].mean().unstack("condition")
    out: Discrepancy = {}
    for group in groups:
        if group not in people.index.get_level_values("group"):
            continue
        traits = people.xs(group, level="group")
        own = means.xs(group, level="group").reindex(traits.index)
        expected = emulator.means(traits.to_numpy(float))
        for m in measures:
            residual = {
                c: own[(m, c)].to_numpy(float) - expected[:, emulator.moments_.index(f"{c}:{m}")]
                for c in ("VO", "HV")
            }
            residual[DIFFERENCE] = residual["HV"] - residual["VO"]
            for label, r in residual.items():
                r = r[np.isfinite(r)]
                if len(r) >= 2:
                    se = float(np.std(r, ddof=1) / np.sqrt(len(r)))
                    out[(group, m, label)] = (float(np.mean(r)), se, len(r))
    return out


def _model_row(
    draws: np.ndarray, correction: tuple[float, float, int] | None, positive: bool = False
) -> dict[str, Any]:
    """The model's predicted mean and 95 % interval from the emulator's `draws` (best fit,
    then the fit's bootstrap replicates) and the emulator's discrepancy (`correction`,
    `emulator_discrepancy`): the prediction moved by the discrepancy, its percentile
    interval widened on each side by the discrepancy's t interval in quadrature.
    `positive` (a condition's mean of a positive measure): the same on the log scale,
    the discrepancy's half-width relative to the mean (the delta method), so that the
    interval stays above zero; where the prediction or the interval's end is not
    positive, the measure's own scale."""
    best = float(draws[0])
    low, high = float(np.percentile(draws[1:], 2.5)), float(np.percentile(draws[1:], 97.5))
    row: dict[str, Any] = {"emulator": best, "emulator_ci": [low, high]}
    if correction is None:
        return {**row, "mean": best, "ci_low": low, "ci_high": high}
    shift, se, n = correction
    half = float(stats.t.ppf(0.975, n - 1)) * se
    centre = best + shift
    if positive and min(low, best, centre) > 0:
        rel = half / centre
        ci_low = centre * float(np.exp(-np.hypot(max(np.log(best / low), 0.0), rel)))
        ci_high = centre * float(np.exp(np.hypot(max(np.log(high / best), 0.0), rel)))
    else:
        ci_low = centre - float(np.hypot(max(best - low, 0.0), half))
        ci_high = centre + float(np.hypot(max(high - best, 0.0), half))
    return {
        **row,
        "mean": centre,
        "ci_low": ci_low,
        "ci_high": ci_high,
        "discrepancy": shift,
        "discrepancy_se": se,
    }


def source_rows(
    source: str,
    frame: pd.DataFrame,
    measures: Sequence[str],
    groups: Sequence[str],
    rng: np.random.Generator,
    n_boot: int,
) -> list[dict[str, Any]]:
    """`summaries`' rows of one source of trials (`observed`, `simulated`): per group,
    measure and condition (and HV - VO) the mean of the participant means with its
    bootstrap 95 % interval: on the log scale for a condition's mean of a positive
    measure (it stays above zero), on the measure's own for the HV - VO difference."""
    rows = []
    for group, m, label, values in condition_values(frame, measures, groups):
        v = values.to_numpy(float)
        positive = label != DIFFERENCE and bool(np.all(v > 0))
        low, high = bootstrap_means(v, rng, n_boot, positive=positive)
        rows.append(
            {
                "group": group,
                "measure": m,
                "condition": label,
                "source": source,
                "n": len(values),
                "mean": float(values.mean()),
                "ci_low": low,
                "ci_high": high,
            }
        )
    return rows


def summaries(
    observed: pd.DataFrame,
    simulated: pd.DataFrame,
    measures: list[str],
    groups: list[str],
    predicted: dict[str, dict[str, list[float]]],
    rng: np.random.Generator,
    n_boot: int,
    discrepancy: Discrepancy | None = None,
) -> list[dict[str, Any]]:
    """Per group, measure and condition (and HV - VO): the observed and simulated mean of
    participant means with bootstrap 95 % intervals, and the fitted model's predicted
    mean with its interval from the fit's bootstrap: the emulator's, corrected by its
    `discrepancy` from the simulated people where given (`_model_row`)."""
    rows = [
        *source_rows("observed", observed, measures, groups, rng, n_boot),
        *source_rows("simulated", simulated, measures, groups, rng, n_boot),
    ]
    for group in groups:
        for m in measures:
            for label in CONDITIONS:
                draws = np.asarray(predicted[group][f"{label}:{m}"])
                rows.append(
                    {
                        "group": group,
                        "measure": m,
                        "condition": label,
                        "source": "model",
                        "n": len(draws) - 1,
                        **_model_row(
                            draws,
                            (discrepancy or {}).get((group, m, label)),
                            positive=label != DIFFERENCE,
                        ),
                    }
                )
    return rows


def power_effects(simulated: pd.DataFrame, measures: list[str]) -> dict[str, Any]:
    """group -> measure -> standardised HV - VO effect and VO-HV correlation of the
    simulated people's means (what `study power --participants` takes)."""
    out: dict[str, Any] = {}
    means = simulated.groupby(["group", "participant", "condition"])[measures].mean()
    for group, g in means.groupby(level="group"):
        out[group] = {}
        for m in measures:
            wide = g[m].unstack()
            sd = np.sqrt((wide["VO"].var() + wide["HV"].var()) / 2)
            effect = float((wide["HV"] - wide["VO"]).mean() / sd) if sd > 0 else 0.0
            rho = float(np.corrcoef(wide["VO"], wide["HV"])[0, 1]) if sd > 0 else 0.0
            out[group][m] = {"effect": round(effect, 4), "correlation": round(rho, 4)}
    return out
