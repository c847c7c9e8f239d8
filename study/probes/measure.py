"""Every probe's measurement model over one participant's stored probe trials: per
trait, an estimate and its standard error. This is the one place the participant fit
(`study.analysis.participant_fit`) reads the probes through (`trait_estimates`,
`probe_table`).

Two passes: a probe whose model needs another's trait (the stall detection and the
comfort torque subtract the reaction time) gets, in the second, what the first pass
estimated; a missing probe leaves its trait out, and the others fall back as their
modules say.
"""

from __future__ import annotations

from collections.abc import Iterable

import pandas as pd

from study.probes import get_probe, probes
from study.probes.base import ProbeTrial, TraitEstimate


def trait_estimates(trials: Iterable[ProbeTrial]) -> dict[str, TraitEstimate]:
    """trait -> its estimate from one participant's probe trials (traits no probe told,
    or whose probe has too few usable trials, are absent)."""
    by_probe: dict[str, list[ProbeTrial]] = {}
    for trial in trials:
        by_probe.setdefault(trial.probe, []).append(trial)
    known: dict[str, TraitEstimate] = {}
    for _ in range(2):
        found = {}
        for name, rows in by_probe.items():
            estimate = get_probe(name).estimate(rows, known)
            if estimate is not None:
                found[estimate.trait] = estimate
        known = found
    return known


def probe_table(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per participant (index: code), per probed trait its estimate (column
    `TRAIT`) and SE (`TRAIT:se`); NaN where the participant has no estimate.

    `trials`: columns participant, probe, trial_index, stimulus, response, correct,
    context (a mapping), driver (`store.probe_frame`)."""
    traits = sorted({p.trait for p in probes()})
    rows = {}
    for code, frame in trials.groupby("participant", sort=True):
        found = trait_estimates(
            ProbeTrial(
                probe=r.probe,
                trial_index=int(r.trial_index),
                stimulus=None if pd.isna(r.stimulus) else float(r.stimulus),
                response=None if pd.isna(r.response) else float(r.response),
                correct=None if pd.isna(r.correct) else bool(r.correct),
                context=r.context or {},
                driver=r.driver,
            )
            for r in frame.itertuples()
        )
        rows[code] = {
            **{t: found[t].value if t in found else float("nan") for t in traits},
            **{f"{t}:se": found[t].se if t in found else float("nan") for t in traits},
        }
    columns = traits + [f"{t}:se" for t in traits]
    return pd.DataFrame.from_dict(rows, orient="index", columns=columns)
