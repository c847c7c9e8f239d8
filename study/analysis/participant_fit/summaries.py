"""The fit's summaries: observed vs simulated per group, condition and measure, and the
effects `study power --participants` takes from the people simulated from the fit."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pandas as pd

from study.analysis.participant_fit.observed import bootstrap_means


def condition_values(
    frame: pd.DataFrame, measures: Sequence[str], groups: Sequence[str]
) -> Iterator[tuple[str, str, str, pd.Series]]:
    """(group, measure, condition, values) per group, measure and condition (VO, HV and
    each person's VO - HV): the people's means of the measure, people with both
    conditions only."""
    means = frame.groupby(["group", "participant", "condition"])[list(measures)].mean()
    for group in groups:
        g = means.xs(group, level="group")
        for m in measures:
            wide = g[m].unstack().dropna()
            yield group, m, "VO", wide["VO"]
            yield group, m, "HV", wide["HV"]
            yield group, m, "VO-HV", wide["VO"] - wide["HV"]


def summaries(
    observed: pd.DataFrame,
    simulated: pd.DataFrame,
    measures: list[str],
    groups: list[str],
    predicted: dict[str, dict[str, list[float]]],
    rng: np.random.Generator,
    n_boot: int,
) -> list[dict[str, Any]]:
    """Per group, measure and condition (and VO - HV): the observed and simulated mean of
    participant means with bootstrap 95 % intervals, and the fitted model's predicted
    mean with its interval from the fit's bootstrap."""
    rows = []
    for source, frame in (("observed", observed), ("simulated", simulated)):
        for group, m, label, values in condition_values(frame, measures, groups):
            low, high = bootstrap_means(values.to_numpy(float), rng, n_boot)
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
    for group in groups:
        for m in measures:
            for label in ("VO", "HV", "VO-HV"):
                draws = np.asarray(predicted[group][f"{label}:{m}"])
                rows.append(
                    {
                        "group": group,
                        "measure": m,
                        "condition": label,
                        "source": "model",
                        "n": len(draws) - 1,
                        "mean": float(draws[0]),
                        "ci_low": float(np.percentile(draws[1:], 2.5)),
                        "ci_high": float(np.percentile(draws[1:], 97.5)),
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
