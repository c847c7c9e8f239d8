"""`study bench participants`: recovery of known trait distributions by the participant fit.

1. A study with known trait distributions (the truth: the hand-set `PROFILES` with every
   trait's mean moved `shift` prior SDs up or down, `truth_profiles`, so that a trait
   left at its prior is not recovered by luck) is simulated through the real session
   runner into SQLite (`study demo --participants` with the truth as MODEL.json):
   `groups` (20/8/8) people, `trials` measured trials per condition, counterbalanced.
2. `study participants fit`'s whole fit runs on it (`fit_study`), timed: the
   target is <= 10 minutes for a 36-participant study on this 2-core machine.
3. The truth's HV - VO differences of the peak forces: `truth_people` more people per
   group drawn from the truth and simulated (1 trial per condition, independent seeds),
   their mean difference per group with its standard error. 300 by default: with 60 the
   truth's own standard error (0.02-0.04 N) was half the fitted model's interval, so a
   truth estimate off by chance could fall outside it.
4. Targets: each group's fitted mean of each trait within 15 % of the truth's (reported
   for every trait, with the mean of the study's own people beside it: with 8 people
   a group's sample mean is itself off its distribution's by about 7 %; and beside the
   count, how often an oracle would meet it, `oracle_within`); the truth's
   HV - VO peak-force difference inside the fitted model's reported
   95 % interval (the `model` rows of the summaries: the emulator's prediction over the
   fit's bootstrap replicates, corrected by its discrepancy from the people simulated
   from the fit; the `simulated` rows' own interval is reported beside it). The fit's
   CPU time is reported beside its wall time: on a machine shared with other jobs, CPU
   seconds / 2 is what the fit takes on 2 idle cores.
5. With `--coverage N`: the share of the fitted group means' 95 % intervals that hold
   the truth over N studies simulated on the fit's emulator (`participant_fit.coverage`).

Everything here is SIMULATED, and the JSON says so (`data_source`).
"""

from __future__ import annotations

import json
import os
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.study import Participant, Study
from study.analysis.participant_fit.coverage import coverage, typical_probe_se
from study.analysis.participant_fit.emulator import MomentEmulator
from study.analysis.participant_fit.estimate import HIGH, LOW, prior_arrays
from study.analysis.participant_fit.fit import FitSettings, fit_study, simulate_people
from study.analysis.participant_fit.summaries import DIFFERENCE
from study.protocol.demo import run_demo
from study.protocol.participant_model import FORMAT, load_model
from study.protocol.session import participant_traits
from study.protocol.traits import PROFILES, TRAIT_BOUNDS, TRAITS, GroupProfile
from teleop_core.progress import Progress, as_step, no_progress

TOLERANCE = 0.15
"""Largest relative error of a recovered group mean."""
SHIFT_SD = 0.7
"""How far the truth's trait means lie from the priors', in prior SDs."""
ORACLE_STUDIES = 20000
"""Simulated studies over which `oracle_within` counts."""


def truth_profiles(shift_sd: float = SHIFT_SD) -> dict[str, GroupProfile]:
    """PROFILES with each trait's mean moved `shift_sd` of its SD, up and down in turn
    over groups and traits (up where down would leave less than one SD to the trait's
    lower bound)."""
    out = {}
    for g, (group, profile) in enumerate(PROFILES.items()):
        moved = {}
        for j, trait in enumerate(TRAITS):
            mean, sd = getattr(profile, trait)
            sign = 1.0 if (g + j) % 2 == 0 else -1.0
            low, high = TRAIT_BOUNDS[trait]
            if mean - shift_sd * sd < low + sd:
                sign = 1.0
            moved[trait] = (float(min(mean + sign * shift_sd * sd, high - sd)), sd)
        out[group] = GroupProfile(**moved)
    return out


def oracle_within(
    truth: dict[str, GroupProfile],
    groups: dict[str, int],
    tolerance: float = TOLERANCE,
    studies: int = ORACLE_STUDIES,
    seed: int = 0,
) -> dict[str, Any]:
    """How often a fit that knew every simulated person's traits exactly (and took each
    group's mean as its people's mean) would be within `tolerance` of the truth's means:
    per group and trait, on average over `studies` studies of `groups` people drawn as a
    session draws them (`draw_traits`: normal, clipped into `TRAIT_BOUNDS`), and in all of
    them at once. What no fit can beat: with 8 people a group's own mean strays from its
    distribution's by chance."""
    rng = np.random.default_rng(seed)
    rows, hits = [], []
    for group, n in groups.items():
        mean, sd = prior_arrays(truth[group])
        people = np.clip(mean + sd * rng.standard_normal((studies, n, len(TRAITS))), LOW, HIGH)
        within = np.abs(people.mean(axis=1) - mean) <= tolerance * np.abs(mean)
        hits.append(within)
        rows += [
            {"group": group, "trait": t, "probability": float(within[:, j].mean())}
            for j, t in enumerate(TRAITS)
        ]
    every = np.concatenate(hits, axis=1)
    counts = every.sum(axis=1)
    return {
        "per_trait": rows,
        "expected_within": float(counts.mean()),
        "all_within_share": float(every.all(axis=1).mean()),
        "at_least_share": {
            int(k): float((counts >= k).mean()) for k in range(every.shape[1], -1, -1)
        },
        "studies": studies,
    }


def _truth_model(path: Path, truth: dict[str, GroupProfile]) -> None:
    """The truth as a MODEL.json `study demo --participants` takes."""
    groups = {
        g: {t: {"mean": getattr(p, t)[0], "sd": getattr(p, t)[1]} for t in TRAITS}
        for g, p in truth.items()
    }
    model = {"format": FORMAT, "task": "lcca", "data_source": "simulated", "groups": groups}
    path.write_text(json.dumps(model))


FORCES = ("peak_proximal_force_n", "peak_distal_force_n")


def run_participants_bench(
    groups: dict[str, int],
    trials: int,
    settings: FitSettings,
    truth_people: int,
    seed: int,
    out_dir: Path | None,
    status: Progress = no_progress,
    shift_sd: float = SHIFT_SD,
    probes: bool = False,
    coverage_studies: int = 0,
    emulator: MomentEmulator | None = None,
) -> dict[str, Any]:
    """The bench's report (see the module docstring); `probes`: every simulated person
    also answers the design's probes before the fit (`study.probes`); with
    `coverage_studies`, the coverage of the fitted means' 95 % intervals over that many
    studies simulated on the fit's emulator (`participant_fit.coverage`); `emulator`: one
    `build_emulator` built with `settings` (several seeds share it), else built."""
    load_before = os.getloadavg()
    truth = truth_profiles(shift_sd)
    with tempfile.TemporaryDirectory() as tmp:
        db = str(Path(tmp) / "truth.db")
        _truth_model(Path(tmp) / "truth.json", truth)
        start = time.monotonic()
        run_demo(
            db,
            seed,
            settings.jobs,
            status,
            participants=str(Path(tmp) / "truth.json"),
            sizes=groups,
            trials_per_condition=trials,
        )
        study_s = time.monotonic() - start
        engine = open_database(db, create=False)
        realized = _realized(engine, Path(tmp) / "truth.json")
        if probes:
            from study.probes.store import run_all_probes

            run_all_probes(engine, load_model(Path(tmp) / "truth.json"), as_step(status, "probes"))
        try:
            start, cpu0 = time.monotonic(), _cpu_s()
            result = fit_study(
                engine,
                "lcca",
                settings,
                "simulated 20/8/8 study",
                lambda step, k=0, n=0: status(f"fit: {step}", k, n),
                emulator,
            )
            fit_s, fit_cpu_s = time.monotonic() - start, _cpu_s() - cpu0
        finally:
            engine.dispose()
    model, table = result.to_dict(), result.table
    covered = (
        _coverage(result, truth, groups, trials, settings, seed, probes, coverage_studies, status)
        if coverage_studies
        else None
    )
    status("the truth's HV - VO differences")
    truth_trials = simulate_people(
        "lcca",
        {g: [truth[g]] for g in groups},
        truth_people,
        1,
        FitSettings(jobs=settings.jobs, seed=seed + 1000),
        lambda *_: None,
    )
    means = truth_trials.groupby(["group", "participant", "condition"])[list(FORCES)].mean()
    oracle = oracle_within(truth, groups, seed=seed)
    chance = {(r["group"], r["trait"]): r["probability"] for r in oracle["per_trait"]}
    recovery, differences = [], []
    for group in groups:
        fitted = model["fit"][group]["traits"]
        for trait in TRAITS:
            true = getattr(truth[group], trait)[0]
            got = fitted[trait]["mean"]
            recovery.append(
                {
                    "group": group,
                    "trait": trait,
                    "identifiable": fitted[trait]["identifiable"],
                    "true": true,
                    "study_people_mean": realized[group][trait],
                    "prior": getattr(PROFILES[group], trait)[0],
                    "fitted": got,
                    "ci95": fitted[trait].get("mean_ci95"),
                    "relative_error": (got - true) / true,
                    "within": abs(got - true) <= TOLERANCE * abs(true),
                    "within_study_people": abs(got - realized[group][trait])
                    <= TOLERANCE * abs(realized[group][trait]),
                    "oracle_within_probability": chance[(group, trait)],
                }
            )
        wide = means.xs(group, level="group")
        for m in FORCES:
            d = (wide[m].unstack()["HV"] - wide[m].unstack()["VO"]).to_numpy(float)
            rows = table[
                (table["group"] == group)
                & (table["measure"] == m)
                & (table["condition"] == DIFFERENCE)
            ].set_index("source")
            row, sim = rows.loc["model"], rows.loc["simulated"]
            true_d = float(d.mean())
            differences.append(
                {
                    "group": group,
                    "measure": m,
                    "truth": true_d,
                    "truth_se": float(d.std(ddof=1) / np.sqrt(len(d))),
                    "model": float(row["mean"]),
                    "model_ci95": [float(row["ci_low"]), float(row["ci_high"])],
                    "within": bool(row["ci_low"] <= true_d <= row["ci_high"]),
                    "emulator": float(row["emulator"]),
                    "emulator_ci95": [float(x) for x in row["emulator_ci"]],
                    "discrepancy": float(row.get("discrepancy", 0.0)),
                    "discrepancy_se": float(row.get("discrepancy_se", 0.0)),
                    "simulated": float(sim["mean"]),
                    "simulated_ci95": [float(sim["ci_low"]), float(sim["ci_high"])],
                    "simulated_within": bool(sim["ci_low"] <= true_d <= sim["ci_high"]),
                }
            )
    if out_dir is not None:
        from study.analysis.participant_fit.figure import fit_figure

        out_dir.mkdir(parents=True, exist_ok=True)
        note = (
            "SIMULATED: a 20/8/8 study simulated with known traits (the hand-set profiles, "
            f"every mean moved {shift_sd:g} prior SDs), fitted by `study participants fit`"
        )
        fit_figure(table, note).savefig(out_dir / "participants_fit.png", dpi=200)
    return {
        "data_source": "simulated",
        "groups": groups,
        "trials_per_condition": trials,
        "settings": settings.__dict__,
        "truth_people_per_group": truth_people,
        "identifiable": model["identifiable"],
        "weak_traits": model["weak_traits"],
        "fixed_at_prior": model["fixed_at_prior"],
        "shrunk_to_prior": model["shrunk_to_prior"],
        "identification_ratio": model["identification_ratio"],
        "probes": model["probes"]["line"],
        "probe_se": _probe_se(result, probes),
        "held_out_trait_error": model["held_out_trait_error"],
        "truth_shift_prior_sds": shift_sd,
        "recovery": recovery,
        "recovery_target": f"within {TOLERANCE:.0%} of the true mean",
        "recovery_met": all(r["within"] for r in recovery),
        "recovery_met_identifiable": all(r["within"] for r in recovery if r["identifiable"]),
        "recovery_within": f"{sum(r['within'] for r in recovery)} of {len(recovery)}",
        "recovery_within_study_people": f"{sum(r['within_study_people'] for r in recovery)} "
        f"of {len(recovery)}",
        "oracle": {
            "expected_within": round(oracle["expected_within"], 2),
            "all_within_share": round(oracle["all_within_share"], 3),
            "at_least_share": {
                k: round(v, 3) for k, v in oracle["at_least_share"].items() if v < 0.9995
            },
            "studies": oracle["studies"],
            "note": "a fit that knew every simulated person's traits exactly, each group's "
            "mean taken as its people's mean, over studies drawn like this one",
        },
        "differences": differences,
        "differences_met": all(d["within"] for d in differences),
        "study_seconds": round(study_s, 1),
        "fit_seconds": round(fit_s, 1),
        "fit_cpu_seconds": round(fit_cpu_s, 1),
        "fit_target_seconds": 600,
        "lacks": model["lacks"]["line"],
        "participant_effects": model["effects_line"],
        "prediction_error": model["prediction_error"],
        "verdict": model["verdict"],
        "coverage": covered,
        "emulator_check": model["emulator_check"]["line"],
        "emulator_check_outside": model["emulator_check"]["outside"],
        "emulator_check_outside_people_only": model["emulator_check"]["outside_people_only"],
        "emulator_check_outside_best_fit": model["emulator_check"]["outside_best_fit"],
        "emulator_check_interval": model["emulator_check"]["interval"],
        "emulator_check_rows": model["emulator_check"]["rows"],
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
        "cpus": os.cpu_count(),
    }


def _coverage(
    result: Any,
    truth: dict[str, GroupProfile],
    groups: dict[str, int],
    trials: int,
    settings: FitSettings,
    seed: int,
    probes: bool,
    studies: int,
    status: Progress,
) -> dict[str, Any]:
    """The coverage of the fit's 95 % intervals over `studies` studies on its emulator,
    each person answering the probes with the study's typical SEs when it ran them."""
    return coverage(
        result.emulator,
        {g: truth[g] for g in groups},
        groups,
        float(trials),
        result.plan.free,
        studies,
        settings.bootstrap,
        seed,
        result.plan.weak,
        as_step(status, "coverage: study"),
        None if not probes else typical_probe_se(result.data.probed),
    )


def _probe_se(result: Any, probes: bool) -> dict[str, list[float]] | None:
    """Per group, each trait's typical probe SE (NaN where no probe tells it), when the
    study ran the probes."""
    if not probes:
        return None
    return {g: v.tolist() for g, v in typical_probe_se(result.data.probed).items()}


def _realized(engine: Any, model_path: Path) -> dict[str, dict[str, float]]:
    """Each group's mean of its study people's own traits (as the session drew them)."""

    model = load_model(model_path)
    with Session(engine) as session:
        seed = session.scalars(select(Study.seed)).one()
        people = session.execute(select(Participant.code, Participant.group)).all()
    drawn: dict[str, list[Any]] = {}
    for code, group in people:
        drawn.setdefault(group, []).append(participant_traits(seed, code, group, model))
    return {
        g: {t: float(np.mean([getattr(p, t) for p in ps])) for t in TRAITS}
        for g, ps in drawn.items()
    }


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (the fit's workers)."""
    own, kids = (
        resource.getrusage(resource.RUSAGE_SELF),
        resource.getrusage(resource.RUSAGE_CHILDREN),
    )
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def markdown(report: dict[str, Any]) -> str:
    """The bench's tables for benchmarks/results/participants_bench.md."""
    lines = [
        "# Participant fit: recovery from a simulated 20/8/8 study (SIMULATED)",
        "",
        f"Identifiable: {', '.join(report['identifiable'])}; "
        + (
            "told weakly, fitted with their group means shrunk towards the priors: "
            f"{', '.join(report['shrunk_to_prior'])}"
            if report["shrunk_to_prior"]
            else f"fixed at their priors: {', '.join(report['fixed_at_prior']) or 'none'}"
        )
        + f". {report.get('probes', 'probes: not run')}. The truth's means lie "
        f"{report['truth_shift_prior_sds']} prior SDs from the priors'; "
        f"{report['recovery_within']} group means within 15 % "
        f"({report['recovery_within_study_people']} within 15 % of the study's own people's "
        "means).",
        "",
        f"An oracle that knew every simulated person's traits exactly, and took each "
        f"group's mean as its people's mean, would have all {len(report['recovery'])} within "
        "15 % in "
        f"{100 * report['oracle']['all_within_share']:.0f} % of studies drawn like this one "
        f"(on average {report['oracle']['expected_within']:.1f} of {len(report['recovery'])}; "
        f"{report['oracle']['studies']} studies): with {min(report['groups'].values())} "
        "people a group's own mean strays "
        "from its distribution's by chance, so no fit meets the target in every study. "
        "`oracle` below: how often the oracle meets it for that mean. The oracle has at "
        "least k within 15 % in this share of studies: "
        + ", ".join(f"{k}: {100 * v:.0f} %" for k, v in report["oracle"]["at_least_share"].items())
        + ".",
        "",
        "| group | trait | prior | true mean | the study's people | fitted (95 % CI) "
        "| error | within 15 % | oracle |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in report["recovery"]:
        fitted = (
            f"{r['fitted']:.4g} (at its prior: not identifiable)"
            if r["ci95"] is None
            else f"{r['fitted']:.4g} ({r['ci95'][0]:.4g}-{r['ci95'][1]:.4g})"
            + ("" if r["identifiable"] else ", shrunk")
        )
        lines.append(
            f"| {r['group']} | {r['trait']} | {r['prior']:.4g} | {r['true']:.4g} "
            f"| {r['study_people_mean']:.4g} | {fitted} | {100 * r['relative_error']:+.1f} % "
            f"| {'yes' if r['within'] else 'NO'} "
            f"| {100 * r['oracle_within_probability']:.0f} % |"
        )
    lines += [
        "",
        "| group | measure | truth HV - VO (SE) | fitted model (95 % CI) | inside "
        "| emulator alone (95 % CI) | discrepancy (SE) | people simulated from the fit |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for d in report["differences"]:
        lines.append(
            f"| {d['group']} | {d['measure']} | {d['truth']:.3f} ({d['truth_se']:.3f}) "
            f"| {d['model']:.3f} ({d['model_ci95'][0]:.3f}, {d['model_ci95'][1]:.3f}) "
            f"| {'yes' if d['within'] else 'NO'} "
            f"| {d['emulator']:.3f} ({d['emulator_ci95'][0]:.3f}, {d['emulator_ci95'][1]:.3f}) "
            f"| {d['discrepancy']:+.3f} ({d['discrepancy_se']:.3f}) "
            f"| {d['simulated']:.3f} ({d['simulated_ci95'][0]:.3f}, "
            f"{d['simulated_ci95'][1]:.3f}) |"
        )
    lines += [
        "",
        f"Fit: {report['fit_seconds']:.0f} s wall, {report['fit_cpu_seconds']:.0f} CPU s "
        f"(target <= 600 s); the study's "
        f"simulation: {report['study_seconds']:.0f} s; load average "
        f"{report['load_average_before']} -> {report['load_average_after']}, "
        f"{report['cpus']} CPUs.",
        "",
        report["lacks"],
        "",
        report["participant_effects"],
        "",
        report["emulator_check"],
        "",
    ]
    c = report.get("coverage")
    if c:
        lines += [
            f"Coverage of the fitted group means' 95 % intervals: {100 * c['coverage']:.1f} % "
            f"of {c['intervals']} intervals over {c['studies']} studies simulated on the "
            f"fit's emulator ({c['bootstrap']} bootstrap replicates each; target "
            f"{100 * c['target'][0]:.0f}-{100 * c['target'][1]:.0f} %).",
            "",
            "| group | trait | coverage |",
            "|---|---|---|",
            *(
                f"| {r['group']} | {r['trait']} | {100 * r['coverage']:.0f} % |"
                for r in c["per_trait"]
            ),
            "",
        ]
    return "\n".join(lines)
