"""Where the participant fit's emulator is off: its predicted group means against fresh
simulations of people drawn from the truth of `study bench participants` (the priors
moved 0.7 SD), per group, condition and measure. SIMULATED throughout.

    # the design's trials (a Latin hypercube over the box, or with --grouped one split
    # across the groups about their priors; --repeats=R trials per condition a setting,
    # default 1) and PER fresh people a group at the truth (3 trials per condition; 0:
    # none; --fresh-seed=S: their seed, default SEED + 500; SEED 0, DESIGN 320 and
    # --repeats=2 are the fit's own design, `build_emulator`'s)
    nice -n 10 python benchmarks/emulator_bias.py simulate SEED DESIGN PER OUT.pkl
    # the comparison: surfaces fitted to the pickles' designs (each, and pooled), against
    # the first fresh people among the pickles; writes OUT.json (--only-local: the
    # fit's surfaces, the cubic and the local emulator only; --design-boot=B: the fit's
    # surfaces' own noise by B bootstrap resamples of the design's settings, and z
    # against the fresh SE and that noise together)
    python benchmarks/emulator_bias.py analyse OUT.json A.pkl [B.pkl ...]

Variants compared (each as z = (prediction - fresh mean) / the fresh mean's SE; an
unbiased emulator gives an RMS z near 1, more by its own design's noise): the
emulator as the fit builds it (a global quadratic surface in the log traits; the
measures' means from a log-link surface of the measures themselves); the means as
before it, exp(log surface) times Duan's smearing factor; with a smearing that follows the
traits (E[exp(residual) | traits] by ridge); a cubic surface; the measures fitted on
their own scale; a surface local to each group (the design's trials weighted by the
group's prior density with its SDs widened `widen` times); and the same as the library
builds it (`MomentEmulator.local`, the residual's statistics weighted too).
"""

from __future__ import annotations

import json
import pickle
import sys
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats
from sklearn.linear_model import RidgeCV

from study.analysis.participant_fit.emulator import (
    ALPHAS,
    LOCAL_WIDEN,
    MomentEmulator,
    design_box,
    design_settings,
    group_design_settings,
    log_moment,
    trial_matrix,
)
from study.analysis.participant_fit.estimate import GroupEstimator, prior_arrays
from study.analysis.participant_fit.fit import FitSettings, simulate_people
from study.analysis.participant_fit.simulate import simulate_settings
from study.bench.participants import truth_profiles
from study.protocol.tasks import get_task
from study.protocol.traits import PROFILES, TRAITS

TASK = get_task("lcca")
MEASURES = list(TASK.analysed_measures)
NAMES = [f"{c}:{m}" for c in ("VO", "HV") for m in MEASURES]
SUMMARY = (
    "rms_z",
    "mean_z",
    "beyond_1_96",
    "of",
    "rms_z_with_design_noise",
    "beyond_1_96_with_design_noise",
    "expected_outside_check_if_unbiased",
)


def simulate(
    seed: int,
    design_n: int,
    per: int,
    out: str,
    grouped: bool = False,
    repeats: int = 1,
    fresh_seed: int | None = None,
) -> None:
    if grouped:
        x = group_design_settings(design_n, seed)[0]
    else:
        x = design_settings(design_n, seed, design_box())
    people = [{"group": "design", **dict(zip(TRAITS, row, strict=True))} for row in x]
    design = simulate_settings("lcca", people, repeats, 2, 180.0, lambda *a: None)
    truth = truth_profiles(0.7)
    fresh = (
        simulate_people(
            "lcca",
            {g: [truth[g]] for g in truth},
            per,
            3,
            FitSettings(jobs=2, seed=seed + 500 if fresh_seed is None else fresh_seed),
            lambda *a: None,
        )
        if per
        else None
    )
    with open(out, "wb") as f:
        pickle.dump({"x": x, "design": design, "fresh": fresh}, f)


def _surface(
    x: np.ndarray, design: pd.DataFrame, emu: MomentEmulator, weights: np.ndarray, kind: str
) -> Any:
    """A predictor of each NAMES moment's expected value (own scale) at trait settings."""
    wide = trial_matrix(design, MEASURES)
    xs = x[wide.index.get_level_values("setting")]
    phi = emu.terms(xs)
    raw = wide[NAMES].to_numpy(float)
    fits = []
    for j in range(len(NAMES)):
        ok = np.isfinite(raw[:, j])
        target = raw[ok, j] if kind == "own_scale" else log_moment(raw[ok, j])
        r = RidgeCV(alphas=list(ALPHAS)).fit(phi[ok], target, sample_weight=weights[ok])
        res = target - r.predict(phi[ok])
        smear = None
        if kind == "local_smearing":
            smear = RidgeCV(alphas=list(ALPHAS)).fit(phi[ok], np.exp(res))
        fits.append((r, float(np.average(np.exp(res), weights=weights[ok])), smear))

    def predict(traits: np.ndarray) -> np.ndarray:
        t = emu.terms(traits)
        cols = []
        for r, smear, local in fits:
            if kind == "own_scale":
                cols.append(r.predict(t))
            elif local is not None:
                cols.append(np.exp(r.predict(t)) * np.maximum(local.predict(t), 0.2))
            else:
                cols.append(np.exp(r.predict(t)) * smear)
        return np.column_stack(cols)

    return predict, xs


def _group_predictions(predict_for: Any, emu: MomentEmulator) -> list[float]:
    """The predicted group means at the truth, in `_compare`'s row order."""
    truth = truth_profiles(0.7)
    out = []
    for g in truth:
        mean, sd = prior_arrays(truth[g])
        draws = GroupEstimator(emu, PROFILES[g], list(range(len(TRAITS))), 3.0).draws(mean, sd)
        pred = dict(zip(NAMES, predict_for(g)(draws).mean(axis=0), strict=True))
        for m in MEASURES:
            for c in ("VO", "HV", "HV-VO"):
                p = pred[f"HV:{m}"] - pred[f"VO:{m}"] if c == "HV-VO" else pred[f"{c}:{m}"]
                out.append(float(p))
    return out


def design_noise(
    x: np.ndarray, design: pd.DataFrame, emu: MomentEmulator, boots: int, mean_surface: bool
) -> np.ndarray:
    """The SD of each `_compare` row's prediction over emulators refitted to `boots`
    resamples of the design's settings (each with its trials): the emulator's own noise,
    which the fresh people's SE leaves out."""
    rng = np.random.default_rng(5)
    preds = []
    for _ in range(boots):
        pick = rng.integers(0, len(x), len(x))
        parts = []
        for new, old in enumerate(pick):
            part = design[design["setting"] == old].copy()
            part["setting"] = new
            parts.append(part)
        e = MomentEmulator(mean_surface=mean_surface).fit(
            x[pick], pd.concat(parts, ignore_index=True), MEASURES, ()
        )
        idx = [e.moments_.index(n) for n in NAMES]
        preds.append(_group_predictions(lambda g, e=e, i=idx: lambda t: e.means(t)[:, i], emu))
    return np.std(preds, axis=0, ddof=1)


CHECK_PEOPLE = 24
"""People a group the fit's emulator check simulates (`FitSettings.check`)."""


def expected_outside(rows: list[dict[str, Any]], fresh_people: int) -> float:
    """How many of `rows` an unbiased emulator with the rows' design noise would put
    outside the emulator check's 95 % intervals: each row's simulated mean has the SE of
    `CHECK_PEOPLE` people (the fresh SE scaled by sqrt(fresh / CHECK_PEOPLE)), and the
    prediction misses it by N(0, SE^2 + noise^2); outside when beyond 1.96 SE."""
    total = 0.0
    for r in rows:
        se = r["fresh_se"] * np.sqrt(fresh_people / CHECK_PEOPLE)
        total += 2 * stats.norm.sf(1.96 * se / np.hypot(se, r["design_noise_sd"]))
    return float(total)


def _compare(
    predict_for: Any,
    fresh: pd.DataFrame,
    emu: MomentEmulator,
    noise: np.ndarray | None = None,
) -> dict[str, Any]:
    """Per row z against the fresh mean's SE; with `noise` (`design_noise`) also
    against sqrt(SE^2 + noise^2)."""
    truth = truth_profiles(0.7)
    per = fresh.groupby(["group", "participant", "condition"])[MEASURES].mean()
    rows = []
    for g in truth:
        mean, sd = prior_arrays(truth[g])
        draws = GroupEstimator(emu, PROFILES[g], list(range(len(TRAITS))), 3.0).draws(mean, sd)
        pred = dict(zip(NAMES, predict_for(g)(draws).mean(axis=0), strict=True))
        people = per.xs(g, level="group")
        for m in MEASURES:
            wide = people[m].unstack()
            for c in ("VO", "HV", "HV-VO"):
                v = (wide["HV"] - wide["VO"]) if c == "HV-VO" else wide[c]
                p = pred[f"HV:{m}"] - pred[f"VO:{m}"] if c == "HV-VO" else pred[f"{c}:{m}"]
                se = float(v.std(ddof=1) / np.sqrt(len(v)))
                rows.append(
                    {
                        "group": g,
                        "condition": c,
                        "measure": m,
                        "fresh": float(v.mean()),
                        "fresh_se": se,
                        "predicted": float(p),
                        "z": float((p - v.mean()) / se),
                    }
                )
    z = np.array([r["z"] for r in rows])
    out: dict[str, Any] = {
        "rms_z": round(float(np.sqrt((z**2).mean())), 3),
        "mean_z": round(float(z.mean()), 3),
        "beyond_1_96": int((np.abs(z) > 1.96).sum()),
        "of": len(z),
    }
    if noise is not None:
        for r, sd in zip(rows, noise, strict=True):
            r["design_noise_sd"] = float(sd)
            r["z_with_design_noise"] = (r["predicted"] - r["fresh"]) / float(
                np.hypot(r["fresh_se"], sd)
            )
        zt = np.array([r["z_with_design_noise"] for r in rows])
        out.update(
            {
                "rms_z_with_design_noise": round(float(np.sqrt((zt**2).mean())), 3),
                "beyond_1_96_with_design_noise": int((np.abs(zt) > 1.96).sum()),
                "expected_outside_check_if_unbiased": round(
                    expected_outside(rows, len(fresh["participant"].unique()) // 3), 2
                ),
            }
        )
    out["rows"] = rows
    return out


def analyse(out: str, paths: list[str], only_local: bool = False, boots: int = 0) -> None:
    loaded = []
    for p in paths:
        with open(p, "rb") as f:
            loaded.append(pickle.load(f))
    fresh = next(d["fresh"] for d in loaded if d["fresh"] is not None)
    results: dict[str, Any] = {}
    designs = {f"{len(d['x'])} settings ({p})": [d] for p, d in zip(paths, loaded, strict=True)}
    if len(loaded) > 1:
        designs[f"{sum(len(d['x']) for d in loaded)} settings (pooled)"] = loaded
    for label, ds in designs.items():
        x = np.concatenate([d["x"] for d in ds])
        parts, offset = [], 0
        for d in ds:
            part = d["design"].copy()
            part["setting"] += offset
            offset += len(d["x"])
            parts.append(part)
        design = pd.concat(parts, ignore_index=True)
        emu = MomentEmulator().fit(x, design, MEASURES, TASK.fit_features)
        idx = [emu.moments_.index(n) for n in NAMES]
        noise = (design_noise(x, design, emu, boots, True) if boots else None, None)
        results[f"{label}: as the fit builds it"] = _compare(
            lambda g, emu=emu, idx=idx: lambda t: emu.means(t)[:, idx], fresh, emu, noise[0]
        )
        if boots:
            noise = (noise[0], design_noise(x, design, emu, boots, False))
        smeared = MomentEmulator(mean_surface=False).fit(x, design, MEASURES, TASK.fit_features)
        results[f"{label}: exp(log surface) x Duan's smearing (the means before)"] = _compare(
            lambda g, s=smeared, i=idx: lambda t: s.means(t)[:, i], fresh, emu, noise[1]
        )
        cubic = MomentEmulator(degree=3).fit(x, design, MEASURES, TASK.fit_features)
        cidx = [cubic.moments_.index(n) for n in NAMES]
        results[f"{label}: cubic"] = _compare(
            lambda g, c=cubic, i=cidx: lambda t: c.means(t)[:, i], fresh, emu
        )
        for widen in (2.0, LOCAL_WIDEN, 3.0):
            local = {g: emu.local(PROFILES[g], widen) for g in PROFILES}
            results[f"{label}: the fit's local emulator, widen {widen:g}"] = _compare(
                lambda g, lo=local, i=idx: lambda t: lo[g].means(t)[:, i], fresh, emu
            )
        if only_local:
            continue
        ones = np.ones(len(trial_matrix(design, MEASURES)))
        for kind in ("local_smearing", "own_scale"):
            predict, _ = _surface(x, design, emu, ones, kind)
            results[f"{label}: {kind}"] = _compare(lambda g, p=predict: p, fresh, emu)
        _, xs = _surface(x, design, emu, ones, "log")
        for widen in (3.0, 2.0, 1.5):
            by_group = {}
            for g in PROFILES:
                m0, s0 = prior_arrays(PROFILES[g])
                w = np.exp(stats.norm.logpdf((xs - m0) / (widen * s0)).sum(axis=1))
                by_group[g] = _surface(x, design, emu, w / w.mean(), "log")[0]
            results[f"{label}: local to each group, widen {widen:g}"] = _compare(
                lambda g, b=by_group: b[g], fresh, emu
            )
    report = {
        "data_source": "simulated",
        "command": "python benchmarks/emulator_bias.py analyse " + " ".join(sys.argv[2:]),
        "fresh_people_per_group": int(fresh["participant"].nunique() / 3),
        "design_bootstrap": boots,
        "summary": {k: {kk: v[kk] for kk in SUMMARY if kk in v} for k, v in results.items()},
        "variants": results,
    }
    with open(out, "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    if sys.argv[1] == "simulate":
        repeats = next((int(a.split("=")[1]) for a in sys.argv if a.startswith("--repeats=")), 1)
        fresh_seed = next(
            (int(a.split("=")[1]) for a in sys.argv if a.startswith("--fresh-seed=")), None
        )
        simulate(
            int(sys.argv[2]),
            int(sys.argv[3]),
            int(sys.argv[4]),
            sys.argv[5],
            "--grouped" in sys.argv,
            repeats,
            fresh_seed,
        )
    else:
        args = [a for a in sys.argv[3:] if not a.startswith("--")]
        boots = next((int(a.split("=")[1]) for a in sys.argv if a.startswith("--design-boot=")), 0)
        analyse(sys.argv[2], args, "--only-local" in sys.argv, boots)
