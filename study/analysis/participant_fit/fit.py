"""The whole fit of simulated participants to a study's trials, and MODEL.json's content.

`run_fit` runs the steps, each a function with its own answer (`read_data` -> `FitData`,
`plan_traits` -> `TraitPlan`, `effects.search` -> `EffectSearch`, `fit_group` ->
`GroupResult`, `check_model` -> `ModelChecks`), gathered in a `FitResult` that writes
MODEL.json (`to_dict`, `write`). `plan_traits` is the one place that decides, per trait,
whether it is fitted from the task's data, held at its prior, or told by another source.

Steps (each reported through `progress(step, k, n)`):
1. the task's trials, their behavioural features read off the stored samples, and each
   person's moments (`observed.py`); refused with one line when a group has too few
   people; the participant effects the residual calls for (`effects.py`: practice,
   fatigue, carry-over), the traits then fitted to the trials with them taken out;
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

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import Engine

from study.analysis.participant_fit import WEAK_TRAITS, checks, effects, validate
from study.analysis.participant_fit.effects import EffectSearch
from study.analysis.participant_fit.emulator import (
    MIN_DEFINED,
    MomentEmulator,
    design_box,
    design_settings,
)
from study.analysis.participant_fit.estimate import (
    HYPER_SD,
    IDENTIFIED_RATIO,
    NU0,
    GroupEstimator,
    GroupFit,
    expanded_interval,
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
from study.analysis.participant_fit.simulate import simulate_settings, worker_pool
from study.analysis.participant_fit.summaries import (
    CONDITIONS,
    DIFFERENCE,
    TRAIT_COLUMNS,
    emulator_discrepancy,
    power_effects,
    source_rows,
    summaries,
)
from study.errors import StudyInputError
from study.probes.measure import probe_arrays, probe_information, probe_summary
from study.protocol.design import KNOWN_CONDITIONS, MAX_TRIAL_S
from study.protocol.participant_effects import ParticipantEffect
from study.protocol.participant_model import FORMAT
from study.protocol.tasks import get_task
from study.protocol.traits import PROFILES, TRAITS, GroupProfile, draw_traits
from teleop_core.blas import one_blas_thread
from teleop_core.files import write_atomically
from teleop_core.progress import Progress, as_step, no_progress


@dataclass(frozen=True)
class FitSettings:
    design: int = 320
    """Trait settings the emulator is built from: with 160, held-out people's reaction
    time was off by noticeably more than with 320 (`validate.py`)."""
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
    seeds of `study bench participants`, shrink put 18-20 of 21 group means
    within 15 % of the truth (prior: 16-17), but its HV - VO peak-force intervals held
    the truth in 3-6 of 6 (prior: 6 of 6): a weak trait absorbs the emulator's local
    bias (the outsiders' comfort torque came out 25 % low with a narrow interval), and
    the predicted forces follow it. So the default holds them."""

    def __post_init__(self) -> None:
        if self.weak_traits not in WEAK_TRAITS:
            raise StudyInputError(
                f"weak traits {self.weak_traits!r}; expected one of {', '.join(WEAK_TRAITS)}"
            )


_no_progress = no_progress


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
    effects: Sequence[ParticipantEffect] = (),
) -> pd.DataFrame:
    """Trials of `per_group` people per group, `k` per condition, with `participant`,
    `group`, `order` (alternating) and `position` as observed. Person i of a group is
    drawn from `profiles[group][i % len]`: one profile (the truth), or the fit's
    bootstrap replicates, so that the people carry the fit's uncertainty too; every
    trial carries the participant `effects` at its place in the person's session."""
    rng = np.random.default_rng([settings.seed, 0xC4EC])
    people = [
        (g, draw_traits(g, rng, {g: ps[i % len(ps)]}))
        for g, ps in profiles.items()
        for i in range(per_group)
    ]
    firsts = [KNOWN_CONDITIONS[i % 2] for i in range(len(people))]
    frame = simulate_settings(
        task,
        [{**t.to_dict(), "first": f} for (_, t), f in zip(people, firsts, strict=True)],
        k,
        settings.jobs,
        settings.max_s,
        as_step(progress, "checking"),
        salt="check",
        effects=effects,
    )
    frame["participant"] = [f"S{i + 1:03d}" for i in frame["setting"]]
    frame["group"] = [people[i][0] for i in frame["setting"]]
    first = np.array(firsts)[frame["setting"].to_numpy()]
    frame["order"] = [f"{f}-first" for f in first]
    block = np.where(frame["condition"] == first, 0, 1)
    frame["position"] = block * k + frame["repeat"]
    frame["trial"] = frame["repeat"] + 1
    frame["driver"] = "simulated"
    traits = np.array([[getattr(t, name) for name in TRAITS] for _, t in people])
    frame[TRAIT_COLUMNS] = traits[frame["setting"].to_numpy()]
    return frame


@one_blas_thread
def build_emulator(
    task: str, settings: FitSettings, progress: Progress = _no_progress
) -> MomentEmulator:
    """Simulate the design's trait settings and fit the emulator of the task's moments."""
    x = design_settings(settings.design, settings.seed, design_box())
    people = [{"group": "design", **dict(zip(TRAITS, row, strict=True))} for row in x]
    design = simulate_settings(
        task,
        people,
        settings.repeats,
        settings.jobs,
        settings.max_s,
        as_step(progress, "emulator"),
    )
    the_task = get_task(task)
    emulator = MomentEmulator().fit(x, design, the_task.analysed_measures, the_task.fit_features)
    progress("validating", 0, 1)
    validate.attach(emulator, x, design, settings.repeats)
    progress("validating", 1, 1)
    return emulator


def features_note(features: list[str], emulator: MomentEmulator) -> str:
    """What the moments hold beyond the measures, and why a task's sample feature is not
    among them: the task has none, or the emulator's design defines it in fewer than
    `MIN_DEFINED` trials of a condition (`MomentEmulator.dropped_features_`)."""
    dropped = getattr(emulator, "dropped_features_", {})
    if features:
        note = (
            "behavioural features read off each trial's samples (the task's "
            "`fit_features`), beside the measures; a trial without samples (imported) "
            "gives the measures only"
        )
    elif not dropped:
        return "the task has no sample features: the measures only"
    else:
        note = "the measures only"
    return note + (f"; {dropped_text(dropped)}" if dropped else "")


def dropped_text(dropped: dict[str, int]) -> str:
    """The task's sample features the emulator dropped (feature -> the most design
    trials of a condition that define it), and why, in words."""
    most = max(dropped.values())
    if not most:
        return (
            f"the task's sample features {', '.join(dropped)} are not in the emulator's "
            "design trials"
        )
    return (
        f"{len(dropped)} of the task's sample features dropped ({', '.join(dropped)}): the "
        f"emulator's design defines each in at most {most} trials of a condition, and a "
        f"feature needs {MIN_DEFINED} (more settings, --design, or repeats, --repeats, "
        "give it more)"
    )


def fit_study(
    engine: Engine,
    task: str,
    settings: FitSettings,
    db_label: str,
    progress: Progress = _no_progress,
    emulator: MomentEmulator | None = None,
) -> FitResult:
    """The fit to the database's completed trials of `task`; `emulator`: one built by
    `build_emulator` with the same `settings` (it depends on them only), else built.
    The simulation workers of the emulator's design and of the check are one pool,
    started first (`worker_pool`)."""
    trials = observed_trials(engine, task)
    check_fittable(trials, task, db_label)
    with worker_pool(task, settings.jobs):
        trials, _ = with_features(engine, trials, task, progress)
        from study.probes.measure import probe_table
        from study.probes.store import probe_frame

        probe_trials = probe_frame(engine)
        probes = probe_table(probe_trials) if len(probe_trials) else None
        emulator = emulator or build_emulator(task, settings, progress)
        return run_fit(trials, task, settings, emulator, db_label, progress, probes=probes)


@dataclass
class FitData:
    """What the fit reads off the trials: each person's moments and the study's shape."""

    trials: pd.DataFrame
    """`observed_trials`' columns, with every emulated feature (NaN where not stored)."""
    measures: list[str]
    groups: list[str]
    people: pd.DataFrame
    """`person_moments`: one row per participant with both conditions."""
    by_group: dict[str, pd.DataFrame]
    ks: dict[str, float]
    """Mean trials per condition of a group's people."""
    sizes: dict[str, np.ndarray]
    """People defining each moment, per group."""
    sampled: int
    """Trials with samples (their features read)."""
    source: str
    counts: dict[str, Any]
    probed: dict[str, np.ndarray] = field(default_factory=dict)
    """Per group, (people, len(TRAITS), 2): each person's probe estimate and SE of each
    trait (NaN where none; `study.probes.measure.probe_arrays`)."""

    def moments(self, group: str, names: list[str]) -> np.ndarray:
        """(people, moments) of a group, log scale; NaN where a feature is undefined."""
        return self.by_group[group][names].to_numpy(float)


def read_data(
    trials: pd.DataFrame,
    task: str,
    emulator: MomentEmulator,
    db_label: str,
    probes: pd.DataFrame | None = None,
) -> FitData:
    """Step 1: the people's moments (and their probe estimates, `probes`:
    `study.probes.measure.probe_table`); one line when a group has too few people."""
    measures = list(get_task(task).analysed_measures)
    groups = check_fittable(trials, task, db_label)
    features = emulator.features_
    trials = trials.assign(**{f: np.nan for f in features if f not in trials})
    people = person_moments(trials, measures, features)
    sampled = int(trials[features].notna().any(axis=1).sum()) if features else 0
    source, counts = data_source(trials)
    names = emulator.moments_
    by_group = {g: people[people["group"] == g] for g in groups}
    return FitData(
        trials=trials,
        measures=measures,
        groups=list(groups),
        people=people,
        by_group=by_group,
        ks={g: float(by_group[g]["k"].mean()) for g in groups},
        sizes={g: by_group[g][names].notna().sum().to_numpy() for g in groups},
        sampled=sampled,
        source=source,
        counts=counts,
        probed={g: probe_arrays(probes, list(by_group[g].index), TRAITS) for g in groups},
    )


TRAIT_ROLES = ("fitted", "prior")
"""How the fit takes a trait: `fitted` from the task's data (with the group mean under
its profile's prior when the data tell it weakly, --weak-traits shrink), `prior` held at
the hand-set profile; any other role names the source that tells the trait's value."""


@dataclass
class TraitPlan:
    """Step 2: per trait, where its value comes from; the one place that decides it."""

    told: list[int]
    """Indices into TRAITS of the traits the task's data identify."""
    free: list[int]
    """Those the fit estimates from the task's data."""
    weak: list[int]
    """Those of `free` the data tell weakly (fitted under their profile's prior)."""
    ratios: dict[str, float]
    held_out: np.ndarray | None
    sources: dict[str, str]
    """trait -> the source that tells its value instead (e.g. a measurement before the
    task); such a trait is neither fitted from the task's data nor held at its prior."""
    probe_info: dict[str, np.ndarray] = field(default_factory=dict)
    """group -> per trait, a person's mean information from the probes in prior SDs
    (`study.probes.measure.probe_information`; 0 where no probe told it)."""
    people: dict[str, int] = field(default_factory=dict)
    """group -> the people whose moments the rule counted."""

    def role(self, trait: str) -> str:
        """`fitted`, `prior`, or the name of the source that tells the trait."""
        if trait in self.sources:
            return self.sources[trait]
        return "fitted" if TRAITS.index(trait) in self.free else "prior"

    @property
    def fixed(self) -> list[str]:
        """Traits held at their hand-set profile."""
        return [t for t in TRAITS if self.role(t) == "prior"]

    def probed_but_held(self) -> dict[str, dict[str, Any]]:
        """Per trait a probe measured but the fit holds at its prior: why. The rule asks
        a group mean's posterior SD below `IDENTIFIED_RATIO` of its prior SD; a person's
        probe gives the information I = (prior SD / SE)^2, and the people spread by one
        prior SD about their mean, so n people alone tell the mean to
        1 / sqrt(1 + n I / (1 + I)) of it (`estimate.identifiable`, the task's trials
        adding theirs). Even an exact probe (I infinite) tells it only to
        1 / sqrt(1 + n): the rule needs n I / (1 + I) > 1 / ratio^2 - 1 = c, so more
        than c people, and then a probe SE below sqrt((n - c) / c) prior SDs. Reported
        in the worst group: the ratio, the probes' typical SE in prior SDs, the SE that
        would do at the group's size (`probe_se_needed`, None when no probe would), and
        the people a group would need at the probes' SE."""
        out: dict[str, dict[str, Any]] = {}
        need = 1.0 / IDENTIFIED_RATIO**2 - 1.0  # n I / (1 + I) must pass this
        for trait in self.fixed:
            j = TRAITS.index(trait)
            infos = {g: float(info[j]) for g, info in self.probe_info.items() if info[j] > 0}
            if not infos:
                continue
            ratio = {
                g: 1.0 / np.sqrt(1.0 + self.people[g] * i / (1.0 + i)) for g, i in infos.items()
            }
            worst = max(ratio, key=lambda g: ratio[g])
            info, n = infos[worst], self.people[worst]
            out[trait] = {
                "group": worst,
                "people": n,
                "probe_se_in_prior_sd": round(float(1.0 / np.sqrt(info)), 3),
                "probe_ratio": round(float(ratio[worst]), 3),
                "ratio": round(float(self.ratios.get(trait, float("nan"))), 3),
                "probe_se_needed": round(float(np.sqrt((n - need) / need)), 3)
                if n > need
                else None,
                "people_needed": int(np.floor(need * (1.0 + info) / info)) + 1,
            }
        return out

    def held_line(self) -> str:
        """Why each probed trait held at its prior is held, in words."""
        why = self.probed_but_held()
        if not why:
            return ""
        return (
            "probed, yet held at their priors: the probes tell these group means too "
            f"weakly for the rule (posterior SD under {IDENTIFIED_RATIO:g} of the prior "
            "SD; --weak-traits shrink fits them under their priors): "
            + "; ".join(
                f"{t} (a person's probe SE {w['probe_se_in_prior_sd']:.1f} prior SDs; group "
                f"{w['group']}'s {w['people']} people tell its mean to {w['ratio']:.2f} of "
                "its prior SD; "
                + (
                    f"a probe SE under {w['probe_se_needed']:.2f} prior SDs (more probe trials) or "
                    if w["probe_se_needed"] is not None
                    else ""
                )
                + f"{w['people_needed']} people a group would tell it)"
                for t, w in why.items()
            )
        )


def plan_traits(
    emulator: MomentEmulator,
    data: FitData,
    settings: FitSettings,
    sources: dict[str, str] | None = None,
) -> TraitPlan:
    """Which traits the data identify (`identifiable`), and so per trait: fitted from the
    task's data, held at the prior (the weakly told ones by default), or told by another
    source (`sources`: trait -> its name)."""
    names = emulator.moments_
    # the features every group's data hold (an imported study without samples: none)
    held = [
        f
        for f in emulator.features_
        if all(
            data.sizes[g][names.index(f"{c}:{f}")] >= 2
            for g in data.groups
            for c in KNOWN_CONDITIONS
        )
    ]
    held_out = validate.held_out_for(emulator, held)
    # a probe's estimate of a trait adds its information (prior SD / SE)^2 to the task's
    probe_info = {
        g: probe_information(data.probed[g], prior_arrays(PROFILES[g])[1])
        for g in data.groups
        if g in data.probed
    } or None
    told, ratios = identifiable(
        emulator,
        {g: PROFILES[g] for g in data.groups},
        data.sizes,
        data.ks,
        held_out,
        validate.held_out_trials(emulator),
        probe_info,
    )
    sources = dict(sources or {})
    told = [j for j in told if TRAITS[j] not in sources]
    # the traits the data tell weakly: held at the profile, or fitted under its prior
    candidates = [j for j in range(len(TRAITS)) if TRAITS[j] not in sources]
    free = candidates if settings.weak_traits == "shrink" else told
    weak = [j for j in free if j not in told]
    people = {g: int(np.max(data.sizes[g])) for g in data.groups}
    return TraitPlan(told, free, weak, ratios, held_out, sources, probe_info or {}, people)


@dataclass
class GroupResult:
    """Step 3's answer for one group: its fit, the bootstrap and the model's predictions."""

    fit: GroupFit
    estimator: GroupEstimator
    boots: np.ndarray
    """(bootstrap, 2 * len(TRAITS)) each replicate's trait means then SDs."""
    predicted: dict[str, list[float]]
    """moment (and `HV-VO:measure`) -> the model's group mean at the fit, then per
    replicate, on the measures' own scale."""
    fixed_cov: np.ndarray
    """The moments' covariance that the traits not told add to a person's."""
    y: np.ndarray
    codes: list[str]
    k: float

    @property
    def profile(self) -> GroupProfile:
        return _profile(self.fit.mean, self.fit.sd)

    @property
    def replicates(self) -> list[GroupProfile]:
        n = len(TRAITS)
        return [_profile(b[:n], b[n:]) for b in self.boots]

    def to_dict(self, plan: TraitPlan, group: str, names: list[str]) -> dict[str, Any]:
        best, n = self.fit, len(TRAITS)
        mean_obs, sd_obs, n_obs = observed_moments(self.y)
        m_fit, s_fit = self.estimator.expected(best.mean, best.sd)

        def trait(j: int, t: str) -> dict[str, Any]:
            out: dict[str, Any] = {
                "mean": float(best.mean[j]),
                "sd": float(best.sd[j]),
                "fitted": j in plan.free,
                "identifiable": j in plan.told,
            }
            if j in plan.free:
                # a trait and its spread are positive: their intervals on the log scale
                out["mean_ci95"] = expanded_interval(
                    self.boots[:, j], len(self.y), positive=True
                ).tolist()
                out["sd_ci95"] = expanded_interval(
                    self.boots[:, n + j], len(self.y), positive=True
                ).tolist()
            if j not in plan.told:
                out["prior"] = list(getattr(PROFILES[group], t))
            return out

        return {
            "participants": len(self.y),
            "trials_per_condition": self.k,
            "traits": {t: trait(j, t) for j, t in enumerate(TRAITS)},
            "moments": {
                m: {
                    "observed_mean": float(mean_obs[i]) if n_obs[i] >= 2 else None,
                    "simulated_mean": float(m_fit[i]),
                    "observed_sd": float(sd_obs[i]) if n_obs[i] >= 2 else None,
                    "simulated_sd": float(s_fit[i]),
                    "participants": int(n_obs[i]),
                }
                for i, m in enumerate(names)
            },
            "people": {
                code: {t: float(best.people[i, j]) for j, t in enumerate(TRAITS) if j in plan.free}
                for i, code in enumerate(self.codes)
            },
            "cost": best.cost,
            "converged": best.success,
        }


def fit_group(
    emulator: MomentEmulator,
    data: FitData,
    group: str,
    plan: TraitPlan,
    settings: FitSettings,
    rng: np.random.Generator,
) -> GroupResult:
    """One group's trait distribution, its bootstrap over participants (resampled, the
    weak traits' prior centre drawn) and the model's predicted means per replicate."""
    names = emulator.moments_
    est = GroupEstimator(
        emulator, PROFILES[group], plan.free, data.ks[group], settings.seed, plan.weak
    )
    y = data.moments(group, names)
    probed = data.probed.get(group)
    best = est.fit(y, probes=probed)
    start = getattr(est, "x_", None)
    boots, preds = [], [_predict(est, best.mean, best.sd)]
    for _ in range(settings.bootstrap):
        pick = rng.integers(0, len(y), len(y))
        b = est.fit(y[pick], start, est.prior_centre(rng), None if probed is None else probed[pick])
        boots.append(np.concatenate([b.mean, b.sd]))
        preds.append(_predict(est, b.mean, b.sd))
    # the moments' spread that the weakly told traits add to a person's (the outlier
    # rule searches the identifiable traits only: the measures alone are 6 moments)
    fixed_only = best.sd.copy()
    fixed_only[plan.told] = 0.0
    fixed_cov = np.atleast_2d(
        np.cov(emulator.log_moments(est.draws(best.mean, fixed_only)), rowvar=False)
    )
    return GroupResult(
        fit=best,
        estimator=est,
        boots=np.array(boots).reshape(len(boots), 2 * len(TRAITS)),
        predicted={key: [p[key] for p in preds] for key in preds[0]},
        fixed_cov=fixed_cov,
        y=y,
        codes=list(data.by_group[group].index),
        k=data.ks[group],
    )


@dataclass
class ModelChecks:
    """Step 4: people simulated from the fit, the summaries and what the model lacks."""

    simulated: pd.DataFrame
    table: pd.DataFrame
    rows: list[dict[str, Any]]
    outliers: dict[str, Any]
    misfit: dict[str, Any]
    emulator_for_simulated: dict[tuple[str, str, str], float] = field(default_factory=dict)
    """(group, measure, condition) -> the emulator's mean for the people simulated
    (`replicate_prediction`), which the emulator check compares."""
    emulator_design_sd: dict[tuple[str, str, str], float] = field(default_factory=dict)
    """(group, measure, condition) -> that mean's SD over the emulator's refits to its
    resampled design (`replicate_design_sd`), which the check counts beside the people's."""
    gaps: dict[str, Any] | None = None
    """`checks.summary_gaps` of `table`: observed means beyond their gap's interval."""
    check_table: pd.DataFrame | None = None
    """The summaries the emulator check reads: `table`, or with participant effects
    added, the simulated people's with the effects taken out (the emulator's people
    have none)."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "line": checks.lacks_line(self.rows, self.outliers, self.misfit, self.gaps),
            "tests": self.rows,
            "outliers": self.outliers,
            "group_means": self.misfit,
            "gaps": self.gaps,
        }


def check_model(
    task: str,
    emulator: MomentEmulator,
    data: FitData,
    plan: TraitPlan,
    fits: dict[str, GroupResult],
    settings: FitSettings,
    rng: np.random.Generator,
    progress: Progress,
    added: Sequence[ParticipantEffect] = (),
) -> ModelChecks:
    """People drawn from the fit's replicates and simulated with the study's design (and
    the `added` participant effects), the observed vs simulated summaries (`data`: the
    trials as observed), and the checks of what the model lacks."""
    measures, groups = data.measures, data.groups
    k_sim = round(float(np.median(data.people["k"])))
    replicates = {g: fits[g].replicates for g in groups}
    simulated = simulate_people(task, replicates, settings.check, k_sim, settings, progress, added)
    rows = checks.trend_and_order(data.trials, simulated, measures)
    means = {g: fits[g].fit.mean for g in groups}
    sim_people = person_moments(simulated, measures, emulator.features_)
    # the outlier rule over the measures' moments: the features' long tails (a single
    # backing-off in a trial) raised false alarms on data simulated from the model itself
    m = len(measures) * len(KNOWN_CONDITIONS)
    outlier = checks.outliers(
        emulator.subset(emulator.moments_[:m]),
        data.people,
        sim_people,
        means,
        {g: fits[g].fixed_cov[:m, :m] for g in groups},
        plan.told,
    )
    predicted = {g: fits[g].predicted for g in groups}
    table_boot = max(settings.bootstrap, 200)
    table = pd.DataFrame(
        summaries(
            data.trials,
            simulated,
            measures,
            groups,
            predicted,
            rng,
            table_boot,
            emulator_discrepancy(simulated, measures, groups, emulator),
        )
    )
    misfit = checks.summary_misfit(data.trials, simulated, measures, groups, plan.fixed)
    for_simulated = {
        (g, m, label): replicate_prediction(predicted[g][f"{label}:{m}"], settings.check)
        for g in groups
        for m in measures
        for label in CONDITIONS
    }
    design_sd = {
        (g, *key): sd
        for g in groups
        for key, sd in replicate_design_sd(fits[g], settings.check, measures).items()
    }
    check_table = table
    if added:
        # the emulator knows people without the participant effects: its check compares
        # the simulated people with the effects taken out again, as the fit took them
        # out of the observed trials (`effects.without_effects`, at each person's traits)
        theta = simulated[TRAIT_COLUMNS].to_numpy(float)
        plain = effects.without_effects(simulated, emulator, added, theta)
        check_table = pd.concat(
            [
                table[table["source"] != "simulated"],
                pd.DataFrame(source_rows("simulated", plain, measures, groups, rng, table_boot)),
            ],
            ignore_index=True,
        )
    gaps = checks.summary_gaps(table, DIFFERENCE)
    return ModelChecks(
        simulated, table, rows, outlier, misfit, for_simulated, design_sd, gaps, check_table
    )


def replicate_design_sd(
    result: GroupResult, people: int, measures: Sequence[str]
) -> dict[tuple[str, str], float]:
    """(measure, condition) -> the SD, over the emulator's mean surfaces refitted to
    resamples of its design (`MomentEmulator.refitted_means`), of the prediction
    `replicate_prediction` makes for `people` people drawn from the fit's replicates
    (person i from replicate i % replicates; the best fit without replicates): the
    emulator's own noise in what the emulator check compares. Empty for an emulator
    without mean surfaces."""
    est, n = result.estimator, len(TRAITS)
    emulator = est.emulator
    names = list(getattr(emulator, "mean_moments_", []))
    if not names:
        return {}
    reps = [(b[:n], b[n:]) for b in result.boots] or [(result.fit.mean, result.fit.sd)]
    used = np.bincount(np.arange(people) % len(reps), minlength=len(reps))
    total = (
        sum(
            c * emulator.refitted_means(est.draws(*reps[r])).mean(axis=1)
            for r, c in enumerate(used)
            if c
        )
        / used.sum()
    )
    out = {}
    for m in measures:
        vo, hv = total[:, names.index(f"VO:{m}")], total[:, names.index(f"HV:{m}")]
        for label, v in (("VO", vo), ("HV", hv), (DIFFERENCE, hv - vo)):
            out[(m, label)] = float(np.std(v, ddof=1))
    return out


def replicate_prediction(draws: Sequence[float], people: int) -> float:
    """The emulator's mean for the people `simulate_people` draws from the fit's
    replicates: `draws` is [best fit, replicate 1, ...] (`GroupResult.predicted`), and
    person i of a group comes from replicate i % replicates, so the prediction is the
    replicates' predictions weighted by their people. (At the best fit alone it would
    stand for another population: the replicates' mixture is wider and centred where
    the bootstrap centres it.) Without replicates, the best fit's."""
    reps = list(draws[1:])
    if not reps:
        return float(draws[0])
    return float(np.mean([reps[i % len(reps)] for i in range(people)]))


@dataclass
class FitResult:
    """The whole fit: its steps' answers, and MODEL.json (`to_dict`, `write`)."""

    task: str
    db_label: str
    settings: FitSettings
    emulator: MomentEmulator
    data: FitData
    plan: TraitPlan
    groups: dict[str, GroupResult]
    checks: ModelChecks
    search: EffectSearch | None = None
    """The loop on the people (`effects.search`): the participant effects added."""

    @property
    def table(self) -> pd.DataFrame:
        """The observed vs simulated summaries (the figure's)."""
        return self.checks.table

    def to_dict(self) -> dict[str, Any]:
        """MODEL.json's content."""
        data, plan, settings = self.data, self.plan, self.settings
        names = self.emulator.moments_
        features = self.emulator.features_
        group_out = {g: r.to_dict(plan, g, names) for g, r in self.groups.items()}
        return {
            "format": FORMAT,
            "task": self.task,
            "data_source": data.source,
            "fitted_from": {
                "database": self.db_label,
                "trials": len(data.trials),
                "participants": len(data.people),
                "trials_by_driver": data.counts["trials_by_driver"],
                "note": data.counts["note"],
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
                "trials_with_samples": data.sampled,
                "dropped": getattr(self.emulator, "dropped_features_", {}),
                "note": features_note(features, self.emulator),
            },
            "identifiable": [TRAITS[j] for j in plan.told],
            "probes": probe_summary(
                data.probed, {g: list(data.by_group[g].index) for g in data.groups}, TRAITS
            ),
            "held_out_trait_error": None
            if plan.held_out is None
            else dict(zip(TRAITS, np.round(plan.held_out, 6).tolist(), strict=True)),
            "weak_traits": settings.weak_traits,
            "fixed_at_prior": plan.fixed,
            "probed_but_held": plan.probed_but_held(),
            "probed_but_held_line": plan.held_line(),
            "shrunk_to_prior": [TRAITS[j] for j in plan.weak],
            "trait_roles": {t: plan.role(t) for t in TRAITS},
            "weak_traits_note": "traits the data tell weakly: held at the hand-set profile "
            "(`fixed_at_prior`, --weak-traits prior) or fitted with their group mean under the "
            f"prior N(the profile's mean, {HYPER_SD:g} of its SD) (`shrunk_to_prior`, "
            "--weak-traits shrink)",
            "identification_ratio": {t: round(r, 3) for t, r in plan.ratios.items()},
            "identification_rule": f"posterior / prior SD of a group mean < {IDENTIFIED_RATIO} "
            "(linearised at the priors, the people's own information on their traits, worst "
            "group)",
            "groups": {
                g: {t: {"mean": v["mean"], "sd": v["sd"]} for t, v in out["traits"].items()}
                for g, out in group_out.items()
            },
            "fit": group_out,
            "emulator": self.emulator.to_dict(),
            "summaries": [
                {k: v for k, v in row.items() if not (isinstance(v, float) and np.isnan(v))}
                for row in self.table.round(6).to_dict(orient="records")
            ],
            "simulated_summaries_note": f"'simulated' rows: {settings.check} people per group "
            "SIMULATED from the fitted model (each from one of the fit's bootstrap replicates, "
            "so the interval holds the fit's uncertainty and the people's); 'model': the "
            "fitted model's mean, the emulator's prediction (`emulator`, with the fit's "
            "bootstrap interval `emulator_ci`) plus its discrepancy from the simulator "
            "(`discrepancy`: the simulated people's mean minus the emulator's at their own "
            "traits, with its SE), the interval the bootstrap's widened by the discrepancy's "
            "t interval in quadrature",
            "lacks": self.checks.to_dict(),
            "emulator_check": checks.emulator_check(
                self.table if self.checks.check_table is None else self.checks.check_table,
                self.checks.emulator_for_simulated,
                self.checks.emulator_design_sd,
            ),
            "effects": power_effects(self.checks.simulated, data.measures),
            **(
                self.search.to_dict(self.checks.outliers["flagged"])
                if self.search is not None
                else {}
            ),
            "settings": settings.__dict__,
        }

    def write(self, path: Path, extra: dict[str, Any] | None = None) -> dict[str, Any]:
        """MODEL.json at `path`, written whole or not at all; its content."""

        model = {**self.to_dict(), **(extra or {})}
        write_atomically(path, json.dumps(model, indent=2, default=float) + "\n")
        return model


@one_blas_thread
def run_fit(
    trials: pd.DataFrame,
    task: str,
    settings: FitSettings,
    emulator: MomentEmulator,
    db_label: str,
    progress: Progress = _no_progress,
    sources: dict[str, str] | None = None,
    loop: bool = True,
    probes: pd.DataFrame | None = None,
) -> FitResult:
    """The fit to `trials` (`observed_trials`' columns, and the features `with_features`
    adds where samples are stored) with a built `emulator`, step by step; `sources`:
    traits told by another source than the task's data (`plan_traits`); `loop`: the
    participant effects the residual calls for are added (`effects.search`), the traits
    then fitted to the trials with those effects taken out; `probes`: the participants'
    probe estimates (`study.probes.measure.probe_table`), each a measurement of a trait
    beside the task's moments."""
    observed = read_data(trials, task, emulator, db_label, probes)
    plan = plan_traits(emulator, observed, settings, sources)
    found, data = None, observed
    if loop:
        found = effects.search(
            observed.trials,
            emulator,
            plan.free,
            plan.weak,
            settings.seed,
            progress=progress,
        )
        if found.effects:
            data = read_data(found.adjusted, task, emulator, db_label, probes)
    rng = np.random.default_rng([settings.seed, 0xB007])
    fits = {}
    for k, g in enumerate(data.groups):
        progress("fitting", k, len(data.groups))
        fits[g] = fit_group(emulator, data, g, plan, settings, rng)
    progress("fitting", len(data.groups), len(data.groups))
    added = found.effects if found is not None else []
    checked = check_model(task, emulator, observed, plan, fits, settings, rng, progress, added)
    return FitResult(task, db_label, settings, emulator, observed, plan, fits, checked, found)


def fit_trials(
    trials: pd.DataFrame,
    task: str,
    settings: FitSettings,
    emulator: MomentEmulator,
    db_label: str,
    progress: Progress = _no_progress,
    probes: pd.DataFrame | None = None,
) -> tuple[dict[str, Any], pd.DataFrame]:
    """MODEL.json's content and the summaries' frame of `run_fit` without the loop on
    the people (what the traits alone explain, and what the checks find they lack);
    `probes` as `run_fit`'s."""
    result = run_fit(
        trials, task, settings, emulator, db_label, progress, loop=False, probes=probes
    )
    return result.to_dict(), result.table


def _predict(est: GroupEstimator, mean: np.ndarray, sd: np.ndarray) -> dict[str, float]:
    """The model's group means on the measures' own scale (and HV - VO), by the emulator."""
    draws = est.emulator.means(est.draws(mean, sd)).mean(axis=0)
    out = dict(zip(est.emulator.moments_, draws.tolist(), strict=True))
    for m in est.emulator.measures_:
        out[f"{DIFFERENCE}:{m}"] = out[f"HV:{m}"] - out[f"VO:{m}"]
    return out
