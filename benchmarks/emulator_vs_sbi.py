"""The participant fit's emulator against neural posterior estimation (the `sbi` package)
on the same simulations: how well each tells a held-out person's traits from their own
trials. SIMULATED throughout.

    # the emulator's design (`build_emulator`'s: a Latin hypercube of DESIGN settings,
    # seed SEED, 2 trials per condition, 2 jobs), or with --offset=K an extra block
    # whose trial seeds follow on from setting K (so that no two blocks share a seed)
    nice -n 10 python benchmarks/emulator_vs_sbi.py simulate SEED DESIGN OUT.pkl [--offset=K]
    # the comparison (needs `pip install sbi` beside torch; not a project dependency):
    # the design's 4 folds (`validate.held_out_errors`'), each method fitted to the
    # other 3 folds plus the first N settings of the extra blocks for each N in
    # --extra (default 0), tested on the held-out fold; writes OUT.json
    nice -n 10 python benchmarks/emulator_vs_sbi.py compare OUT.json DESIGN.pkl [EXTRA.pkl ...]
        [--extra=0,320,960] [--npe-seeds=1] [--estimators=maf] [--samples=1000] [--threads=2]
    # under the fit's prior: N people a group drawn from the profiles (--profiles), each
    # estimated by the emulator (the design and the first N extra settings) under their
    # group's profile, and by NPE trained on the other 3 folds of those people
    nice -n 10 python benchmarks/emulator_vs_sbi.py simulate SEED N PEOPLE.pkl --profiles --offset=K
    nice -n 10 python benchmarks/emulator_vs_sbi.py profiles OUT.json PEOPLE.pkl DESIGN.pkl \
        [EXTRA.pkl ...] [--extra=0,2240] [--npe-seeds=1] [--threads=1]
    # markdown tables of either JSON
    python benchmarks/emulator_vs_sbi.py table OUT.json

torch's threads (--threads): 1 on a machine loaded by others, where 2 threads spin
against the other processes and a budget's training takes many times as long.

Each held-out setting is one person with the design's trials (2 per condition): their
summaries are `observed.person_moments`' (per condition, the mean over their trials of
each log measure and log feature, over the moments the fold's emulator keeps), what the
emulator's held-out check reads. The methods:

- the emulator: `MomentEmulator` fitted to the training settings' trials, each held-out
  person's traits its posterior mode under the check's wide prior (the design box's
  centre, its half-width as SD) by `GroupEstimator`, as `validate.held_out_errors`
  (whose numbers the budget 0 reproduces);
- NPE: `sbi`'s neural posterior estimation (a masked autoregressive flow, sbi's
  default) of the traits (the surface's scale: the log of each, the caution as it is)
  given the summaries (a feature undefined in both trials: the training mean, with an
  indicator of its absence), trained on the training settings' own summaries (one
  simulated person each); the estimate is the posterior mean in trait units (sampled);
- two references: the training settings' mean (no data), and a ridge regression of the
  traits (surface scale) on the same summaries (what an amortised point estimate gets
  with no network).

Costs: CPU seconds (the process and its workers) of the simulations, of each method's
fit per fold, and of estimating the held-out people.
"""

from __future__ import annotations

import json
import os
import pickle
import resource
import sys
import time
from typing import Any

import numpy as np
import pandas as pd

from study.analysis.participant_fit import validate
from study.analysis.participant_fit.emulator import (
    MomentEmulator,
    design_box,
    design_settings,
    surface_traits,
)
from study.analysis.participant_fit.estimate import GroupEstimator
from study.analysis.participant_fit.observed import person_moments
from study.analysis.participant_fit.simulate import _new_pool, simulate_setting
from study.protocol.design import MAX_TRIAL_S
from study.protocol.tasks import get_task
from study.protocol.traits import PROFILES, TRAITS, GroupProfile, draw_traits

TASK = "lcca"
REPEATS = 2
JOBS = 2


def _cpu_s() -> float:
    """CPU seconds of this process and its reaped children (the pool's workers)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def simulate(seed: int, n: int, out: str, offset: int = 0, profiles: bool = False) -> None:
    """`build_emulator`'s design simulation (`simulate_settings`, salt `fit`: VO and HV
    of a repeat share a seed), with the trial seeds of setting k those of setting
    offset + k; the rows' `setting` stays 0..n-1. With `profiles`: n people a group
    drawn from the groups' profiles (`draw_traits`) instead of the design's box."""
    if profiles:
        rng = np.random.default_rng([seed, 0x5B1])
        drawn = [draw_traits(g, rng) for g in PROFILES for _ in range(n)]
        x = np.array([[getattr(t, name) for name in TRAITS] for t in drawn])
        groups = [t.group for t in drawn]
    else:
        x = design_settings(n, seed, design_box())
        groups = ["design"] * n
    people = [
        {"group": g, **dict(zip(TRAITS, row, strict=True))}
        for g, row in zip(groups, x, strict=True)
    ]
    n = len(people)
    cpu0, wall0 = _cpu_s(), time.perf_counter()
    rows: list[dict[str, Any]] = []
    with _new_pool(TASK, JOBS) as pool:
        futures = {
            pool.submit(simulate_setting, TASK, offset + k, p, REPEATS, MAX_TRIAL_S): k
            for k, p in enumerate(people)
        }
        for done, future in enumerate(futures, 1):
            rows += [{"setting": futures[future], **r} for r in future.result()]
            if done % 40 == 0:
                print(f"simulated {done}/{n}", file=sys.stderr, flush=True)
    trials = pd.DataFrame(rows).sort_values(["setting", "repeat", "condition"], kind="stable")
    cost = {
        "cpu_s": round(_cpu_s() - cpu0, 1),
        "wall_s": round(time.perf_counter() - wall0, 1),
        "load_average": os.getloadavg(),
    }
    meta = {
        "seed": seed,
        "settings": n,
        "drawn_from": "profiles" if profiles else "design box",
        "repeats": REPEATS,
        "offset": offset,
        **cost,
    }
    with open(out, "wb") as f:
        block = {"x": x, "groups": groups, "trials": trials.reset_index(drop=True), "meta": meta}
        pickle.dump(block, f)
    print(json.dumps(meta))


def _load(paths: list[str]) -> tuple[np.ndarray, pd.DataFrame, int, list[dict[str, Any]]]:
    """The design's and the extra blocks' settings and trials as one: the design's
    settings first (0..DESIGN-1), each block's after the ones before it."""
    xs, frames, metas = [], [], []
    start = 0
    for path in paths:
        with open(path, "rb") as f:
            block = pickle.load(f)
        xs.append(block["x"])
        frames.append(block["trials"].assign(setting=block["trials"]["setting"] + start))
        metas.append(block["meta"])
        start += len(block["x"])
    return np.vstack(xs), pd.concat(frames, ignore_index=True), len(xs[0]), metas


def _people(trials: pd.DataFrame, measures: list[str], emulator: MomentEmulator) -> pd.DataFrame:
    """Each setting's summaries, as `validate.held_out_errors` reads a held-out one."""
    people = trials.assign(participant=trials["setting"].astype(str), group="design", order="")
    out = person_moments(people, measures, emulator.features_)
    out.index = out.index.astype(int)
    return out.sort_index()[emulator.moments_]


def _from_surface(theta: np.ndarray) -> np.ndarray:
    """`surface_traits`' inverse: the exp of each trait but the caution."""
    out = np.array(theta, dtype=float, copy=True)
    logged = surface_traits(np.full((1, len(TRAITS)), np.e))[0] == 1.0
    out[..., logged] = np.exp(out[..., logged])
    return out


def _inputs(train: pd.DataFrame, test: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """The summaries as a network takes them: an undefined feature as the training
    mean, beside an indicator of its absence (for a moment undefined in some training
    settings); moments the training settings never vary dropped."""
    mean = train.mean()
    cols_tr, cols_te = [train.fillna(mean).to_numpy(float)], [test.fillna(mean).to_numpy(float)]
    gaps = [c for c in train.columns if train[c].isna().any()]
    if gaps:
        cols_tr.append(train[gaps].isna().to_numpy(float))
        cols_te.append(test[gaps].isna().to_numpy(float))
    xtr, xte = np.hstack(cols_tr), np.hstack(cols_te)
    varied = xtr.std(axis=0) > 0
    return xtr[:, varied], xte[:, varied]


def _emulator(x, trials, train, test, measures, features, wide):
    """`validate.held_out_errors`' emulator on one fold -> (estimates, fit CPU s,
    estimation CPU s, the fitted emulator)."""
    cpu = time.process_time()
    emulator = MomentEmulator(mean_surface=False).fit(
        x, trials[trials["setting"].isin(train)], measures, features
    )
    fit_s = time.process_time() - cpu
    cpu = time.process_time()
    y = _people(trials[trials["setting"].isin(test)], measures, emulator).to_numpy(float)
    est = GroupEstimator(emulator, wide, list(range(len(TRAITS))), float(REPEATS))
    mu, sd = est.mu0, est.sd0
    theta, _, _ = est.posteriors(y, mu, sd, np.tile(mu, (len(y), 1)), validate.STEPS)
    return theta, fit_s, time.process_time() - cpu, emulator


def _npe(theta_tr, x_tr, x_te, box, seed, samples, estimator):
    """sbi's NPE trained on (theta_tr, x_tr) -> (posterior means in trait units at
    x_te, training CPU s, sampling CPU s, epochs)."""
    import torch
    from sbi.inference import NPE
    from sbi.utils import BoxUniform

    torch.manual_seed(seed)
    prior = BoxUniform(
        low=torch.tensor(box[0], dtype=torch.float32),
        high=torch.tensor(box[1], dtype=torch.float32),
    )
    cpu = time.process_time()
    inference = NPE(prior=prior, density_estimator=estimator, show_progress_bars=False)
    inference.append_simulations(
        torch.tensor(theta_tr, dtype=torch.float32), torch.tensor(x_tr, dtype=torch.float32)
    )
    net = inference.train()
    train_s = time.process_time() - cpu
    epochs = int(inference.summary["epochs_trained"][-1])
    posterior = inference.build_posterior(net)
    cpu = time.process_time()
    draws = (
        posterior.sample_batched(
            (samples,),
            x=torch.tensor(x_te, dtype=torch.float32),
            show_progress_bars=False,
            reject_outside_prior=False,
        )
        .detach()
        .numpy()
    )
    means, leaked = _truncated_means(draws.astype(float), box)
    return means, train_s, time.process_time() - cpu, epochs, leaked


def _truncated_means(
    draws: np.ndarray, box: tuple[np.ndarray, np.ndarray]
) -> tuple[np.ndarray, float]:
    """(samples, people, traits) on the surface's scale -> each person's mean in trait
    units over the draws inside the prior's box (the posterior as sbi's rejection
    sampling truncates it, without its wait for a whole batch's slowest person), and
    the share of draws outside. A person with no draw inside: the draws clipped."""
    inside = ((draws >= box[0]) & (draws <= box[1])).all(axis=2)
    values = _from_surface(draws)
    w = inside[..., None].astype(float)
    n = w.sum(axis=0)
    clipped = _from_surface(np.clip(draws, box[0], box[1])).mean(axis=0)
    means = np.where(n > 0, (values * w).sum(axis=0) / np.maximum(n, 1), clipped)
    return means, float(1 - inside.mean())


def _ridge(theta_tr: np.ndarray, x_tr: np.ndarray, x_te: np.ndarray) -> np.ndarray:
    from sklearn.linear_model import RidgeCV
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    model = make_pipeline(StandardScaler(), RidgeCV(alphas=np.logspace(-3, 3, 13)))
    return _from_surface(model.fit(x_tr, theta_tr).predict(x_te))


def _rms(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.sqrt(((est - truth) ** 2).mean(axis=0))


def _budget(x, trials, n_design, extra, opts) -> dict[str, Any]:
    """Every method over the design's 4 folds, each fold trained on the other 3 and the
    first `extra` settings of the extra blocks."""
    the_task = get_task(TASK)
    measures, features = list(the_task.analysed_measures), list(the_task.fit_features)
    design_x = x[:n_design]
    low, high = design_x.min(axis=0), design_x.max(axis=0)
    centre, half = (low + high) / 2, (high - low) / 2
    wide = GroupProfile(**{t: (float(centre[j]), float(half[j])) for j, t in enumerate(TRAITS)})
    lo, hi = design_box()
    box = (surface_traits(lo[None])[0], surface_traits(hi[None])[0])
    seeds = int(opts.get("npe-seeds", 1))
    estimators = opts.get("estimators", "maf").split(",")
    fold = np.arange(n_design) % validate.FOLDS
    extra_ids = np.arange(n_design, n_design + extra)
    est: dict[str, list[np.ndarray]] = {}
    cost: dict[str, list[float]] = {}
    truth, epochs, leakage = [], [], []

    def keep(name: str, values: np.ndarray, *costs: tuple[str, float]) -> None:
        est.setdefault(name, []).append(values)
        for key, value in costs:
            cost.setdefault(f"{name}:{key}", []).append(value)

    for f in range(validate.FOLDS):
        test = np.flatnonzero(fold == f)
        train = np.concatenate([np.flatnonzero(fold != f), extra_ids])
        # the settings simulated so far: their range is the emulator's box (the
        # estimates' bounds), the design's alone at budget 0 as in `validate`
        x_sim = x[: n_design + extra]
        theta, fit_s, est_s, emulator = _emulator(
            x_sim, trials, train, test, measures, features, wide
        )
        keep("emulator", theta, ("fit_cpu_s", fit_s), ("estimate_cpu_s", est_s))
        people_tr = _people(trials[trials["setting"].isin(train)], measures, emulator)
        people_te = _people(trials[trials["setting"].isin(test)], measures, emulator)
        truth.append(x[people_te.index])
        theta_tr = surface_traits(x[people_tr.index])
        x_tr, x_te = _inputs(people_tr, people_te)
        keep("no data (training mean)", np.tile(x[people_tr.index].mean(axis=0), (len(x_te), 1)))
        keep("ridge on the summaries", _ridge(theta_tr, x_tr, x_te))
        for estimator in estimators:
            for s in range(seeds):
                means, train_s, sample_s, n_ep, leaked = _npe(
                    theta_tr,
                    x_tr,
                    x_te,
                    box,
                    1000 * f + s,
                    int(opts.get("samples", 1000)),
                    estimator,
                )
                keep(
                    f"npe_{estimator}_seed{s}",
                    means,
                    ("fit_cpu_s", train_s),
                    ("estimate_cpu_s", sample_s),
                )
                epochs.append(n_ep)
                leakage.append(leaked)
        print(
            f"extra {extra}: fold {f} done, CPU s {time.process_time():.0f}, "
            f"load {os.getloadavg()[0]:.1f}",
            file=sys.stderr,
            flush=True,
        )
    truth_all = np.concatenate(truth)
    n_test = len(truth_all)
    none = _rms(np.concatenate(est["no data (training mean)"]), truth_all)
    methods: dict[str, Any] = {}
    for name, parts in est.items():
        rms = _rms(np.concatenate(parts), truth_all)
        entry: dict[str, Any] = {
            "rms_error": dict(zip(TRAITS, rms.round(6).tolist(), strict=True)),
            "rms_error_over_no_data": dict(
                zip(TRAITS, (rms / none).round(3).tolist(), strict=True)
            ),
        }
        fit = cost.get(f"{name}:fit_cpu_s")
        if fit:
            entry["fit_cpu_s_per_fold"] = round(float(np.mean(fit)), 2)
            entry["estimate_cpu_ms_per_person"] = round(
                1000 * float(np.sum(cost[f"{name}:estimate_cpu_s"])) / n_test, 2
            )
        methods[name] = entry
    return {
        "extra_settings": extra,
        "settings_simulated": n_design + extra,
        "multiple_of_design": (n_design + extra) / n_design,
        "training_settings_per_fold": int(n_design * 3 / 4) + extra,
        "held_out_people": n_test,
        "npe_epochs": epochs,
        "npe_share_of_draws_outside_box": [round(v, 4) for v in leakage],
        "methods": methods,
    }


def _have_sbi(command: str) -> bool:
    try:
        import sbi  # noqa: F401
        import torch  # noqa: F401
    except ImportError:
        print(
            f"{command} needs the sbi package (pip install sbi, beside torch); "
            "it is not a dependency of the project",
            file=sys.stderr,
        )
        return False
    return True


def compare(out: str, paths: list[str], opts: dict[str, str]) -> int:
    if not _have_sbi("compare"):
        return 2
    import sbi
    import torch

    torch.set_num_threads(int(opts.get("threads", 2)))
    x, trials, n_design, metas = _load(paths)
    extras = [int(e) for e in opts.get("extra", "0").split(",")]
    if max(extras) > len(x) - n_design:
        print(
            f"--extra {max(extras)}; expected at most the extra blocks' "
            f"{len(x) - n_design} settings",
            file=sys.stderr,
        )
        return 2
    wall0 = time.perf_counter()
    report: dict[str, Any] = {
        "data_source": "SIMULATED",
        "task": TASK,
        "versions": {"sbi": sbi.__version__, "torch": torch.__version__},
        "torch_threads": torch.get_num_threads(),
        "repeats": REPEATS,
        "folds": validate.FOLDS,
        "options": opts,
        "simulations": metas,
        "validate_held_out_errors": None,
        "budgets": [],
    }
    if 0 in extras:
        the_task = get_task(TASK)
        check = validate.held_out_errors(
            x[:n_design],
            trials[trials["setting"] < n_design],
            list(the_task.analysed_measures),
            list(the_task.fit_features),
            REPEATS,
        )
        report["validate_held_out_errors"] = dict(zip(TRAITS, check.round(6).tolist(), strict=True))
    for extra in extras:
        cpu0, start = time.process_time(), time.perf_counter()
        result = _budget(x, trials, n_design, extra, opts)
        used, cpu = 0, 0.0
        for m in metas:
            take = min(m["settings"], n_design + extra - used)
            cpu += m["cpu_s"] * take / m["settings"]
            used += take
        result["simulation_cpu_s"] = round(cpu, 1)
        result["budget_cpu_s"] = round(time.process_time() - cpu0, 1)
        result["budget_wall_s"] = round(time.perf_counter() - start, 1)
        result["load_average_end"] = os.getloadavg()
        report["budgets"].append(result)
        report["compare_wall_s"] = round(time.perf_counter() - wall0, 1)
        # written after each budget, so that a stopped run keeps what it measured
        with open(out, "w") as f:
            json.dump(report, f, indent=1)
    return 0


def _summaries(rms: dict[str, np.ndarray], none: np.ndarray) -> dict[str, Any]:
    return {
        name: {
            "rms_error": dict(zip(TRAITS, r.round(6).tolist(), strict=True)),
            "rms_error_over_no_data": dict(zip(TRAITS, (r / none).round(3).tolist(), strict=True)),
        }
        for name, r in rms.items()
    }


def compare_profiles(out: str, people_path: str, paths: list[str], opts: dict[str, str]) -> int:
    """The same under the fit's prior: people drawn from the groups' profiles, each
    estimated by the emulator (fitted to the design and the first `extra` extra
    settings) under their group's profile (`GroupEstimator`, every trait free), and by
    NPE trained on the other 3 folds of the profiles' people (their group as an input
    beside the summaries: the profiles' mixture as its prior)."""
    if not _have_sbi("profiles"):
        return 2
    import sbi
    import torch

    torch.set_num_threads(int(opts.get("threads", 2)))
    the_task = get_task(TASK)
    measures, features = list(the_task.analysed_measures), list(the_task.fit_features)
    x, trials, n_design, metas = _load(paths)
    with open(people_path, "rb") as f:
        block = pickle.load(f)
    px, ptrials, groups = block["x"], block["trials"], np.array(block["groups"])
    lo, hi = design_box()
    lo, hi = np.minimum(lo, px.min(axis=0)), np.maximum(hi, px.max(axis=0))
    box = (surface_traits(lo[None])[0], surface_traits(hi[None])[0])
    fold = np.arange(len(px)) % validate.FOLDS
    onehot = (groups[:, None] == np.array(list(PROFILES))[None]).astype(float)
    seeds = int(opts.get("npe-seeds", 1))
    budgets = []
    extras = [int(e) for e in opts.get("extra", "0").split(",")]
    for extra in [0, *(e for e in extras if e != 0)]:
        cpu = time.process_time()
        emulator = MomentEmulator(mean_surface=False).fit(
            x[: n_design + extra], trials[trials["setting"] < n_design + extra], measures, features
        )
        fit_s = time.process_time() - cpu
        people = _people(ptrials, measures, emulator)
        y = people.to_numpy(float)
        cpu = time.process_time()
        theta = np.zeros_like(px)
        for g, profile in PROFILES.items():
            idx = np.flatnonzero(groups[people.index] == g)
            est = GroupEstimator(emulator, profile, list(range(len(TRAITS))), float(REPEATS))
            mu, sd = est.mu0, est.sd0
            t, _, _ = est.posteriors(y[idx], mu, sd, np.tile(mu, (len(idx), 1)), validate.STEPS)
            theta[people.index[idx]] = t
        est_s = time.process_time() - cpu
        rms = {"emulator (group's profile as prior)": _rms(theta, px)}
        costs = {
            "emulator (group's profile as prior)": {
                "simulated_settings": n_design + extra,
                "fit_cpu_s": round(fit_s, 2),
                "estimate_cpu_ms_per_person": round(1000 * est_s / len(px), 2),
            }
        }
        if extra == 0:
            none, ridge, npe = np.zeros_like(px), np.zeros_like(px), {}
            npe_cost: dict[str, list[float]] = {}
            for f in range(validate.FOLDS):
                tr, te = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
                x_tr, x_te = _inputs(people.loc[tr], people.loc[te])
                x_tr, x_te = np.hstack([x_tr, onehot[tr]]), np.hstack([x_te, onehot[te]])
                theta_tr = surface_traits(px[tr])
                for g in PROFILES:
                    none[te[groups[te] == g]] = px[tr[groups[tr] == g]].mean(axis=0)
                ridge[te] = _ridge(theta_tr, x_tr, x_te)
                for s in range(seeds):
                    means, train_s, sample_s, _, leaked = _npe(
                        theta_tr,
                        x_tr,
                        x_te,
                        box,
                        1000 * f + s,
                        int(opts.get("samples", 1000)),
                        "maf",
                    )
                    npe.setdefault(f"npe_maf_seed{s}", np.zeros_like(px))[te] = means
                    npe_cost.setdefault(f"npe_maf_seed{s}", []).extend([train_s, sample_s, leaked])
                print(f"profiles: fold {f} done", file=sys.stderr, flush=True)
            rms["no data (group's training mean)"] = _rms(none, px)
            rms["ridge on the summaries and the group"] = _rms(ridge, px)
            for name, m in npe.items():
                rms[name] = _rms(m, px)
                c = np.array(npe_cost[name]).reshape(-1, 3)
                costs[name] = {
                    "simulated_settings": len(px),
                    "training_people_per_fold": int(len(px) * 3 / 4),
                    "fit_cpu_s_per_fold": round(float(c[:, 0].mean()), 2),
                    "estimate_cpu_ms_per_person": round(1000 * float(c[:, 1].sum()) / len(px), 2),
                    "share_of_draws_outside_box": c[:, 2].round(4).tolist(),
                }
            baseline = rms["no data (group's training mean)"]
        budgets.append({"extra_settings": extra, "rms": rms, "costs": costs})
    report = {
        "data_source": "SIMULATED",
        "task": TASK,
        "versions": {"sbi": sbi.__version__, "torch": torch.__version__},
        "people": {g: int((groups == g).sum()) for g in PROFILES},
        "repeats": REPEATS,
        "options": opts,
        "simulations": [*metas, block["meta"]],
        "load_average_end": os.getloadavg(),
        "budgets": [
            {
                "extra_settings": b["extra_settings"],
                "methods": _summaries(b["rms"], baseline),
                "costs": b["costs"],
            }
            for b in budgets
        ],
    }
    with open(out, "w") as f:
        json.dump(report, f, indent=1)
    return 0


SHORT = {
    "preferred_speed_m_s": "speed",
    "reaction_s": "reaction",
    "steering_error_rad": "steering",
    "caution": "caution",
    "haptic_threshold_n_m": "haptic thr.",
    "visual_stall_s": "visual stall",
    "comfort_torque_n_m": "comfort torque",
}


def table(path: str) -> int:
    """Markdown tables of a `compare` or `profiles` JSON: per budget and method, each
    trait's RMS error as a share of the no-data error (trait units below), and costs."""
    with open(path) as f:
        report = json.load(f)
    head = "| method | " + " | ".join(SHORT[t] for t in TRAITS) + " | fit CPU s | ms/person |"
    for b in report["budgets"]:
        size = b.get("settings_simulated", "profiles' people;")
        print(f"\n{size} settings simulated (extra {b['extra_settings']})\n")
        print(head)
        print("|---" * (len(TRAITS) + 3) + "|")
        for name, m in b["methods"].items():
            ratio = " | ".join(f"{m['rms_error_over_no_data'][t]:.2f}" for t in TRAITS)
            c = m if "fit_cpu_s_per_fold" in m else b.get("costs", {}).get(name, {})
            fit = c.get("fit_cpu_s_per_fold", c.get("fit_cpu_s", ""))
            print(f"| {name} | {ratio} | {fit} | {c.get('estimate_cpu_ms_per_person', '')} |")
    return 0


def _options(argv: list[str]) -> tuple[list[str], dict[str, str]]:
    args = [a for a in argv if not a.startswith("--")]
    opts = dict((a[2:] + "=").split("=")[:2] for a in argv if a.startswith("--"))
    return args, opts


def main(argv: list[str]) -> int:
    args, opts = _options(argv)
    if args[:1] == ["simulate"] and len(args) == 4:
        simulate(
            int(args[1]), int(args[2]), args[3], int(opts.get("offset", 0)), "profiles" in opts
        )
        return 0
    if args[:1] == ["table"] and len(args) == 2:
        return table(args[1])
    if args[:1] == ["profiles"] and len(args) >= 4:
        return compare_profiles(args[1], args[2], args[3:], opts)
    if args[:1] == ["compare"] and len(args) >= 3:
        return compare(args[1], args[2:], opts)
    print(__doc__.split("\n\n")[1], file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
