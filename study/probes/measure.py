"""Every probe's measurement model over one participant's stored probe trials: per
trait, an estimate and its standard error. This is the one place the participant fit
(`study.analysis.participant_fit`) reads the probes through (`trait_estimates`,
`probe_table`).

A probe whose model needs another probe's trait (`needs`: the stall detection and the
comfort torque subtract the reaction time) is estimated after the probes that need
none, and gets their estimates; a missing probe leaves its trait out, and the others
fall back as their modules say.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
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
    # first the probes that need no other trait, then those that do (`needs`)
    ordered = sorted(by_probe, key=lambda name: bool(getattr(get_probe(name), "needs", ())))
    for name in ordered:
        estimate = get_probe(name).estimate(by_probe[name], dict(known))
        if estimate is not None:
            known[estimate.trait] = estimate
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


def probe_arrays(
    table: pd.DataFrame | None, codes: list[str], traits: tuple[str, ...]
) -> np.ndarray:
    """(people, traits, 2): for the participants `codes` in order, each trait's probe
    estimate and SE from `probe_table`'s frame; NaN where a person has none (or no
    probe tells the trait)."""
    out = np.full((len(codes), len(traits), 2), np.nan)
    if table is None:
        return out
    for j, trait in enumerate(traits):
        if trait in table:
            out[:, j, 0] = table[trait].reindex(codes).to_numpy(float)
            out[:, j, 1] = table[f"{trait}:se"].reindex(codes).to_numpy(float)
    return out


def probe_information(arrays: np.ndarray, prior_sd: np.ndarray) -> np.ndarray:
    """Per trait, a person's mean information on it from the probes, in prior SDs:
    (prior SD / SE)^2, 0 for a person without the probe (the group's mean over its
    people, as `identifiable` linearises)."""
    se = arrays[:, :, 1]
    info = np.where(
        np.isfinite(se) & (se > 0), (prior_sd[None] / np.where(se > 0, se, 1.0)) ** 2, 0.0
    )
    return info.mean(axis=0) if len(info) else np.zeros(len(prior_sd))


def missing_line(
    arrays_by_group: dict[str, tuple[list[str], np.ndarray]], traits: tuple[str, ...]
) -> dict[str, list[str]]:
    """participant -> the probed traits it has no estimate of, for the participants who
    have some probe estimate but not all (those without any probe are all missing)."""
    probed = [
        j
        for j in range(len(traits))
        if any(np.isfinite(a[:, j, 0]).any() for _, a in arrays_by_group.values())
    ]
    missing = {}
    for codes, arrays in arrays_by_group.values():
        for i, code in enumerate(codes):
            lacks = [traits[j] for j in probed if not np.isfinite(arrays[i, j, 0])]
            if lacks:
                missing[code] = lacks
    return missing


def _by_lacking(missing: dict[str, list[str]]) -> dict[tuple[str, ...], list[str]]:
    """The lacking traits -> the codes that lack exactly them (sorted), in the order of
    their first code."""
    out: dict[tuple[str, ...], list[str]] = {}
    for code, lacks in sorted(missing.items()):
        out.setdefault(tuple(lacks), []).append(code)
    return out


def code_runs(codes: list[str]) -> str:
    """Sorted participant codes with runs of consecutive numbers under one prefix (and
    one width) written as a range: P002, P003, P004, P009 -> "P002-P004, P009"."""
    runs: list[list[str]] = []
    last: tuple[str, int, int] | None = None
    for code in codes:
        head = code.rstrip("0123456789")
        tail = code[len(head) :]
        key = (head, len(tail), int(tail)) if tail else None
        if runs and key and last and key[:2] == last[:2] and key[2] == last[2] + 1:
            runs[-1].append(code)
        else:
            runs.append([code])
        last = key
    return ", ".join(r[0] if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs)


def probe_summary(
    probed: dict[str, np.ndarray], codes: dict[str, list[str]], traits: tuple[str, ...]
) -> dict[str, Any]:
    """MODEL.json's `probes`: which traits the probes measured, for how many people, who
    lacks which, and one line saying so."""
    by_group = {g: (codes[g], probed[g]) for g in probed}
    measured = {
        traits[j]: int(sum(np.isfinite(a[:, j, 0]).sum() for a in probed.values()))
        for j in range(len(traits))
    }
    measured = {t: n for t, n in measured.items() if n}
    people = sum(len(c) for c in codes.values())
    missing = missing_line(by_group, traits) if measured else {}
    if not measured:
        line = "probes: none stored; the traits the task tells weakly rest on the task alone"
    elif missing:
        shown = "; ".join(
            f"{code_runs(cs)} {'lacks' if len(cs) == 1 else f'({len(cs)}) lack'} "
            f"{', '.join(t) if len(t) < len(measured) else 'every probe'}"
            for t, cs in _by_lacking(missing).items()
        )
        line = (
            f"probes: {len(measured)} traits measured; {len(missing)} of {people} "
            f"participants fitted without some: {shown}"
        )
    else:
        line = f"probes: {len(measured)} traits measured for all {people} participants"
    return {"measured": measured, "participants": people, "missing": missing, "line": line}
