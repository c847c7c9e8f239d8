"""The whole fit of simulated participants to a study's trials, and MODEL.json's content.

Steps (each reported through `progress(step, k, n)`):
1. the task's trials, their behavioural features read off the stored samples, and each
   person's moments (`observed.py`); refused with one line when a group has too few
   people;
2. the emulator: `design` trait settings over the priors' range, `repeats` trials per
   condition each, simulated once (`simulate.py`), the response surface fitted
   (`emulator.py`);
3. which traits the moments identify, and each group's trait means and SDs by the
   hierarchical model (`estimate.py`: each person's traits, then the group's), with a
   bootstrap over participants (resampled within group, the weak traits' prior centre
   drawn from their prior, refitted on
   the emulator) for their uncertainty and that of the model's predicted means;
4. people drawn from the fitted model and simulated with the study's design (`check`
   per group, each from one of the fit's bootstrap replicates, the observed trials per
   condition, both orders): the observed vs simulated summaries (the simulated ones are
   the fitted model's prediction: their intervals hold the fit's uncertainty and the
   people's), the effects `study power` takes, and the checks of what the model lacks
   (`checks.py`). The emulator's own prediction is reported beside them (`model`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import Engine

from study.analysis.participant_fit import WEAK_TRAITS, checks, validate
from study.analysis.participant_fit.emulator import MomentEmulator, design_box, design_settings
from study.analysis.participant_fit.estimate import (
    HYPER_SD,
    IDENTIFIED_RATIO,
    NU0,
    GroupEstimator,
    identifiable,
    observed_moments,
    prior_arrays,
)
from study.analysis.participant_fit.observed import (
    check_fittable,
    data_source,
    observed_trials,
    person_moments,
    with_features,
)
from study.analysis.participant_fit.simulate import simulate_settings
from study.analysis.participant_fit.summaries import power_effects, summaries
from study.errors import StudyInputError
from study.probes.measure import probe_arrays, probe_information, probe_summary
from study.protocol.design import KNOWN_CONDITIONS, MAX_TRIAL_S
from study.protocol.participant_model import FORMAT
from study.protocol.tasks import get_task
from study.protocol.traits import PROFILES, TRAITS, GroupProfile, draw_traits


@dataclass(frozen=True)
class FitSettings:
    design: int = 320
    """Trait settings the emulator is built from: held-out people's reaction time was
    off by 1.13 novice prior SDs with 160, by 0.79 with 320 (`validate.py`, 2026-11-26)."""
    repeats: int = 2
    """Trials per condition at each setting."""
    check: int = 24
    """People per group simulated from the fitted model (summaries and checks)."""
    bootstrap: int = 100
    jobs: int = 2
    seed: int = 0
    max_s: float = MAX_TRIAL_S
    weak_traits: str = "prior"
    """What becomes of the traits the data tell weakly: `prior` holds them at the hand-set
    profile; `shrink` fits them with their group mean under the profile's prior. On three
    seeds of `study bench participants` (2026-11-26), shrink put 18-20 of 21 group means
    within 15 % of the truth (prior: 16-17), but its VO - HV peak-force intervals held
    the truth in 3-6 of 6 (prior: 6 of 6): a weak trait absorbs the emulator's local
    bias (the outsiders' comfort torque came out 25 % low with a narrow interval), and
    the predicted forces follow it. So the default holds them."""

    def __post_init__(self) -> None:
        if self.weak_traits not in WEAK_TRAITS:
            raise StudyInputError(
                f"weak traits {self.weak_traits!r}; expected one of {', '.join(WEAK_TRAITS)}"
            )


Progress = Callable[[str, int, int], None]


def _no_progress(step: str, k: int, n: int) -> None:
    return None


def _profile(mean: np.ndarray, sd: np.ndarray) -> GroupProfile:
    return GroupProfile(
        **{t: (float(m), float(s)) for t, m, s in zip(TRAITS, mean, sd, strict=True)}
    )


def simulate_people(
    task: str,
    profiles: dict[str, list[GroupProfile]],
    per_group: int,
    k: int,
    settings: FitSettings,
    progress: Progress,
) -> pd.DataFrame:
    """Trials of `per_group` people per group, `k` per condition, with `participant`,
    `group`, `order` (alternating) and `position` as observed. Person i of a group is
    drawn from `profiles[group][i % len]`: one profile (the truth), or the fit's
    bootstrap replicates, so that the people carry the fit's uncertainty too."""
    rng = np.random.default_rng([settings.seed, 0xC4EC])
    people = [(g, draw_traits(g, rng, {g: ps[i % len(ps)]}))
              for g, ps in profiles.items() for i in range(per_group)]  # fmt: skip
    frame = simulate_settings(
        task,
        [t.to_dict() for _, t in people],
        k,
        settings.jobs,
        settings.max_s,
        lambda a, b: progress("checking", a, b),
        salt="check",
    )
    frame["participant"] = [f"S{i + 1:03d}" for i in frame["setting"]]
    frame["group"] = [people[i][0] for i in frame["setting"]]
    first = np.where(frame["setting"] % 2 == 0, "VO", "HV")
    frame["order"] = [f"{f}-first" for f in first]
    block = np.where(frame["condition"] == first, 0, 1)
    frame["position"] = block * k + frame["repeat"]
    frame["trial"] = frame["repeat"] + 1
    frame["driver"] = "simulated"
    return frame


def build_emulator(task: str, settings: FitSettings,
                   progress: Progress = _no_progress) -> MomentEmulator:  # fmt: skip
    """Simulate the design's trait settings and fit the emulator of the task's moments."""
    x = design_settings(settings.design, settings.seed, design_box())
    people = [{"group": "design", **dict(zip(TRAITS, row, strict=True))} for row in x]
    design = simulate_settings(task, people, settings.repeats, settings.jobs, settings.max_s,
                               lambda a, b: progress("emulator", a, b))  # fmt: skip
    the_task = get_task(task)
    emulator = MomentEmulator().fit(x, design, the_task.analysed_measures, the_task.fit_features)
    progress("validating", 0, 1)
    validate.attach(emulator, x, design, settings.repeats)
    progress("validating", 1, 1)
    return emulator


def fit_participants(
    engine: Engine,
    task: str,
    settings: FitSettings,
    db_label: str,
    progress: Progress = _no_progress,
) -> tuple[dict[str, Any], pd.DataFrame]:
    """MODEL.json's content, and the summaries' frame (for the figure)."""
    trials = observed_trials(engine, task)
    check_fittable(trials, task, db_label)
    trials, _ = with_features(engine, trials, task, lambda a, b: progress("samples", a, b))
    from study.probes.measure import probe_table
    from study.probes.store import probe_frame

    probe_trials = probe_frame(engine)
    probes = probe_table(probe_trials) if len(probe_trials) else None
    return fit_trials(trials, task, settings, build_emulator(task, settings, progress),
                      db_label, progress, probes)  # fmt: skip


def fit_trials(
    trials: pd.DataFrame,
    task: str,
    settings: FitSettings,
    emulator: MomentEmulator,
    db_label: str,
    progress: Progress = _no_progress,
    probes: pd.DataFrame | None = None,
) -> tuple[dict[str, Any], pd.DataFrame]:
    """The fit to `trials` (`observed_trials`' columns, and the features `with_features`
    adds where samples are stored) with a built `emulator`; `probes`: the participants'
    probe estimates (`study.probes.measure.probe_table`), each a measurement of a trait
    beside the task's moments."""
    measures = list(get_task(task).analysed_measures)
    groups = check_fittable(trials, task, db_label)
    features = emulator.features_
    trials = trials.assign(**{f: np.nan for f in features if f not in trials})
    people = person_moments(trials, measures, features)
    sampled = int(trials[features].notna().any(axis=1).sum()) if features else 0
    source, counts = data_source(trials)
    names = emulator.moments_
    by_group = {g: people[people["group"] == g] for g in groups}
    ks = {g: float(by_group[g]["k"].mean()) for g in groups}
    sizes = {g: by_group[g][names].notna().sum().to_numpy() for g in groups}
    # the features every group's data hold (an imported study without samples: none)
    held = [
        f
        for f in features
        if all(sizes[g][names.index(f"{c}:{f}")] >= 2 for g in groups for c in KNOWN_CONDITIONS)
    ]
    held_out = validate.held_out_for(emulator, held)
    probed = {g: probe_arrays(probes, list(by_group[g].index), TRAITS) for g in groups}
    probe_info = {g: probe_information(probed[g], prior_arrays(PROFILES[g])[1]) for g in groups}
    told, ratios = identifiable(emulator, {g: PROFILES[g] for g in groups}, sizes, ks, held_out,
                                validate.held_out_trials(emulator), probe_info)  # fmt: skip
    # the traits the data tell weakly: held at the profile, or fitted under its prior
    shrink = settings.weak_traits == "shrink"
    free = list(range(len(TRAITS))) if shrink else told
    weak = [j for j in free if j not in told]
    rng = np.random.default_rng([settings.seed, 0xB007])
    fitted, group_out, predicted, fixed_cov, replicates = {}, {}, {}, {}, {}
    for k, g in enumerate(groups):
        progress("fitting", k, len(groups))
        est = GroupEstimator(emulator, PROFILES[g], free, ks[g], settings.seed, weak)
        y = by_group[g][names].to_numpy(float)
        best = est.fit(y, probes=probed[g])
        start = getattr(est, "x_", None)
        boots, preds = [], [_predict(est, best.mean, best.sd)]
        for _ in range(settings.bootstrap):
            pick = rng.integers(0, len(y), len(y))
            b = est.fit(y[pick], start, est.prior_centre(rng), probed[g][pick])
            boots.append(np.concatenate([b.mean, b.sd]))
            preds.append(_predict(est, b.mean, b.sd))
        boots_arr = np.array(boots)
        fitted[g] = _profile(best.mean, best.sd)
        replicates[g] = [_profile(b[: len(TRAITS)], b[len(TRAITS) :]) for b in boots_arr]
        # the moments' spread that the weakly told traits add to a person's (the outlier
        # rule searches the identifiable traits only: the measures alone are 6 moments)
        fixed_only = best.sd.copy()
        fixed_only[told] = 0.0
        fixed_cov[g] = np.atleast_2d(
            np.cov(emulator.log_moments(est.draws(best.mean, fixed_only)), rowvar=False)
        )
        predicted[g] = {key: [p[key] for p in preds] for key in preds[0]}
        mean_obs, sd_obs, n_obs = observed_moments(y)
        m_fit, s_fit = est.expected(best.mean, best.sd)
        group_out[g] = {
            "participants": len(y),
            "trials_per_condition": ks[g],
            "traits": {
                t: {
                    "mean": float(best.mean[j]),
                    "sd": float(best.sd[j]),
                    "fitted": j in free,
                    "identifiable": j in told,
                    **(
                        {
                            "mean_ci95": np.percentile(boots_arr[:, j], [2.5, 97.5]).tolist(),
                            "sd_ci95": np.percentile(
                                boots_arr[:, len(TRAITS) + j], [2.5, 97.5]
                            ).tolist(),
                        }
                        if j in free
                        else {}
                    ),
                    **({} if j in told else {"prior": list(getattr(PROFILES[g], t))}),
                }
                for j, t in enumerate(TRAITS)
            },
            "moments": {
                n: {
                    "observed_mean": float(mean_obs[i]) if n_obs[i] >= 2 else None,
                    "simulated_mean": float(m_fit[i]),
                    "observed_sd": float(sd_obs[i]) if n_obs[i] >= 2 else None,
                    "simulated_sd": float(s_fit[i]),
                    "participants": int(n_obs[i]),
                }
                for i, n in enumerate(names)
            },
            "people": {
                code: {t: float(best.people[i, j]) for j, t in enumerate(TRAITS) if j in free}
                for i, code in enumerate(by_group[g].index)
            },
            "cost": best.cost,
            "converged": best.success,
        }
    progress("fitting", len(groups), len(groups))
    k_sim = round(float(np.median(people["k"])))
    simulated = simulate_people(task, replicates, settings.check, k_sim, settings, progress)
    rows = checks.trend_and_order(trials, simulated, measures)
    means = {g: np.array([getattr(fitted[g], t)[0] for t in TRAITS]) for g in groups}
    sim_people = person_moments(simulated, measures, features)
    # the outlier rule over the measures' moments: the features' long tails (a single
    # backing-off in a trial) raised false alarms on data simulated from the model itself
    m = len(measures) * len(KNOWN_CONDITIONS)
    outlier = checks.outliers(
        emulator.subset(names[:m]),
        people,
        sim_people,
        means,
        {g: fixed_cov[g][:m, :m] for g in groups},
        told,
    )
    table = pd.DataFrame(
        summaries(trials, simulated, measures, groups, predicted, rng, max(settings.bootstrap, 200))
    )
    held = [t for j, t in enumerate(TRAITS) if j not in free]
    misfit = checks.summary_misfit(trials, simulated, measures, groups, held)
    model = {
        "format": FORMAT,
        "task": task,
        "data_source": source,
        "fitted_from": {
            "database": db_label,
            "trials": len(trials),
            "participants": len(people),
            "trials_by_driver": counts["trials_by_driver"],
            "note": counts["note"],
        },
        "method": "hierarchical model fitted by EM on an emulator (quadratic response "
        "surface of log measures and log sample features on log traits): each person's "
        "traits N(group mean, group sd), their posterior modes by Levenberg-Marquardt "
        f"(Laplace covariances); group sds pooled with {NU0:g} pseudo-people at the "
        "profile's; the weakly told traits' group means under the profile's prior; "
        "bootstrap over participants, each replicate with the prior's centre drawn from "
        "the prior (randomised maximum likelihood); a person's probe estimate of a trait "
        "(study.probes, with its SE) a measurement of that trait beside the moments",
        "moments": names,
        "features": {
            "names": features,
            "trials_with_samples": sampled,
            "note": "behavioural features read off each trial's samples (the task's "
            "`fit_features`), beside the measures; a trial without samples (imported) "
            "gives the measures only"
            if features
            else "the task has no sample features: the measures only",
        },
        "identifiable": [TRAITS[j] for j in told],
        "probes": probe_summary(probed, {g: list(by_group[g].index) for g in groups}, TRAITS),
        "held_out_trait_error": None
        if held_out is None
        else dict(zip(TRAITS, np.round(held_out, 6).tolist(), strict=True)),
        "weak_traits": settings.weak_traits,
        "fixed_at_prior": [t for j, t in enumerate(TRAITS) if j not in free],
        "shrunk_to_prior": [TRAITS[j] for j in weak],
        "weak_traits_note": "traits the data tell weakly: held at the hand-set profile "
        "(`fixed_at_prior`, --weak-traits prior) or fitted with their group mean under the "
        f"prior N(the profile's mean, {HYPER_SD:g} of its SD) (`shrunk_to_prior`, "
        "--weak-traits shrink)",
        "identification_ratio": {t: round(r, 3) for t, r in ratios.items()},
        "identification_rule": f"posterior / prior SD of a group mean < {IDENTIFIED_RATIO} "
        "(linearised at the priors, the people's own information on their traits, worst "
        "group)",
        "groups": {
            g: {t: {"mean": v["mean"], "sd": v["sd"]} for t, v in group_out[g]["traits"].items()}
            for g in groups
        },
        "fit": group_out,
        "emulator": emulator.to_dict(),
        "summaries": table.round(6).to_dict(orient="records"),
        "simulated_summaries_note": f"'simulated' rows: {settings.check} people per group "
        "SIMULATED from the fitted model (each from one of the fit's bootstrap replicates, so "
        "the interval holds the fit's uncertainty and the people's); 'model': the "
        "emulator's prediction with the fit's bootstrap interval",
        "lacks": {
            "line": checks.lacks_line(rows, outlier, misfit),
            "tests": rows,
            "outliers": outlier,
            "group_means": misfit,
        },
        "emulator_check": checks.emulator_check(table),
        "effects": power_effects(simulated, measures),
        "settings": settings.__dict__,
    }
    return model, table


def _predict(est: GroupEstimator, mean: np.ndarray, sd: np.ndarray) -> dict[str, float]:
    """The model's group means on the measures' own scale (and VO - HV), by the emulator."""
    draws = est.emulator.means(est.draws(mean, sd)).mean(axis=0)
    out = dict(zip(est.emulator.moments_, draws.tolist(), strict=True))
    for m in est.emulator.measures_:
        out[f"VO-HV:{m}"] = out[f"VO:{m}"] - out[f"HV:{m}"]
    return out
