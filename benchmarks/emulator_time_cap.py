"""The experts' completion time: is the emulator's mean surface bent by the trials that
reach the give-up limit (the cap) in the design's slow corners? SIMULATED throughout.

    python benchmarks/emulator_time_cap.py OUT.json EMULATOR.pkl DESIGN.pkl

EMULATOR.pkl: `build_emulator`'s (the fit's design); DESIGN.pkl: `emulator_bias.py
simulate`'s on the same design (its settings, trials and fresh people at the bench's
truth, `--fresh-seed`'s people redrawn here with their traits, as `simulate_people`
draws them). Each variant refits the measures' mean surfaces on the design's trials
(the emulator's terms) and is set against the fresh people twice: at their own traits
(the surface alone, without the population's draws) and for the truth's population
(`emulator_bias._compare`: z over the 27 summaries against the fresh mean's SE).

Variants: as built (a log-link surface of each measure); the capped trials left out;
every trial of a setting with a capped trial left out; the time's mean as a share of
its cap through a logit link (a fractional-logit, quasi-binomial, surface of
time / cap: a mean that cannot pass the cap, so the slow corners need not bend the
surface), penalties 1e-4 and 1e-3; a cubic log-link surface; two parts (the uncapped
trials' mean and the cap's chance); the log time as a censored normal regression; the
quadratic with each trait's cube, or with the log speed squared times each trait.
"""

from __future__ import annotations

import json
import pickle
import sys
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd
from scipy import optimize, stats
from sklearn.preprocessing import PolynomialFeatures

from benchmarks.emulator_bias import NAMES, _compare
from study.analysis.participant_fit.emulator import (
    LOGIT_LINK,
    MomentEmulator,
    fit_mean_surface,
    glm_ridge,
    surface_traits,
    trial_matrix,
)
from study.bench.participants import truth_profiles
from study.protocol.design import MAX_TRIAL_S
from study.protocol.traits import TRAITS, draw_traits

Predict = Callable[[np.ndarray], np.ndarray]


def logit_ridge(
    phi: np.ndarray, y: np.ndarray, w: np.ndarray, alpha: float, steps: int = 60
) -> tuple[np.ndarray, float]:
    """(coef, intercept) minimising mean_w(Bernoulli deviance of y in [0, 1]) / 2 +
    alpha / 2 |coef|^2 of a logit-link model (fractional logit), by the emulator's
    `glm_ridge`, the solver of `poisson_ridge` for the log link."""
    return glm_ridge(phi, y, w, alpha, LOGIT_LINK, steps)


def variants(emu: MomentEmulator, x: np.ndarray, design: pd.DataFrame) -> dict[str, Predict]:
    wide = trial_matrix(design, emu.measures_)[NAMES]
    s = wide.index.get_level_values("setting").to_numpy()
    y = wide.to_numpy(float)
    capped = y >= MAX_TRIAL_S - 0.05
    setting_capped = pd.Series(capped.any(axis=1)).groupby(s).transform("any").to_numpy()
    powers3 = PolynomialFeatures(3).fit(np.zeros((1, len(TRAITS)))).powers_

    def quadratic(t: np.ndarray) -> np.ndarray:
        return emu.terms(t)[:, 1:]

    def cubic(t: np.ndarray) -> np.ndarray:
        z = (surface_traits(np.atleast_2d(t)) - emu.centre_) / emu.scale_
        return np.prod(z[:, None, :] ** powers3[None], axis=2)[:, 1:]

    speed = TRAITS.index("preferred_speed_m_s")

    def pure_cubes(t: np.ndarray) -> np.ndarray:
        z = (surface_traits(np.atleast_2d(t)) - emu.centre_) / emu.scale_
        return np.column_stack([quadratic(t), z**3])

    def speed_cubes(t: np.ndarray) -> np.ndarray:
        z = (surface_traits(np.atleast_2d(t)) - emu.centre_) / emu.scale_
        return np.column_stack([quadratic(t), z[:, [speed]] ** 2 * z])

    def surface(keep: np.ndarray | None = None, terms=quadratic, logit: float = 0.0) -> Predict:
        phi = terms(x[s])
        fits: list[tuple[Any, ...]] = []
        for j, name in enumerate(NAMES):
            ok = np.isfinite(y[:, j]) & (True if keep is None else keep[:, j])
            if logit and name.endswith("completion_time_s"):
                c, i = logit_ridge(
                    phi[ok], np.clip(y[ok, j] / MAX_TRIAL_S, 0, 1), np.ones(ok.sum()), logit
                )
                fits.append(("logit", c, i))
            else:
                c, i, sc = fit_mean_surface(phi[ok], np.maximum(y[ok, j], 0), np.ones(ok.sum()))
                fits.append(("log", c, i, sc))

        def predict(t: np.ndarray) -> np.ndarray:
            ph = terms(t)
            cols = []
            for f in fits:
                if f[0] == "logit":
                    cols.append(MAX_TRIAL_S / (1 + np.exp(-(ph @ f[1] + f[2]))))
                else:
                    cols.append(np.exp(ph @ f[1] + f[2]) * f[3])
            return np.column_stack(cols)

        return predict

    def two_part(alpha: float, linear: bool) -> Predict:
        """E[T] = (1 - p) m + p cap: m the log-link mean of the uncapped trials, p the
        chance of reaching the cap by a logit surface of the capped trials (on the
        linear terms only, or all of them)."""
        uncapped = surface(~capped)
        n_lin = len(TRAITS)
        phi = quadratic(x[s])
        cap_fits = {}
        for j, name in enumerate(NAMES):
            if name.endswith("completion_time_s"):
                ok = np.isfinite(y[:, j])
                ph = phi[ok, :n_lin] if linear else phi[ok]
                cap_fits[j] = logit_ridge(ph, capped[ok, j].astype(float), np.ones(ok.sum()), alpha)

        def predict(t: np.ndarray) -> np.ndarray:
            out = uncapped(t)
            ph = quadratic(t)
            for j, (c, i) in cap_fits.items():
                pr = 1 / (1 + np.exp(-((ph[:, :n_lin] if linear else ph) @ c + i)))
                out[:, j] = (1 - pr) * out[:, j] + pr * MAX_TRIAL_S
            return out

        return predict

    def censored(alpha: float) -> Predict:
        """The log time as a censored normal regression (Tobit: the capped trials
        right-censored at log cap, one spread), its mean below the cap in closed form:
        E[min(T, c)] = exp(mu + s^2 / 2) Phi((log c - mu - s^2) / s) + c (1 - Phi((log c
        - mu) / s))."""
        base = surface()
        phi = np.column_stack([np.ones(len(s)), quadratic(x[s])])
        log_cap = np.log(MAX_TRIAL_S)
        fits = {}
        for j, name in enumerate(NAMES):
            if not name.endswith("completion_time_s"):
                continue
            ok = np.isfinite(y[:, j])
            z, cens, ph = np.log(np.maximum(y[ok, j], 1e-3)), capped[ok, j], phi[ok]
            start = np.linalg.lstsq(ph, z, rcond=None)[0]

            def nll(theta: np.ndarray, z=z, cens=cens, ph=ph) -> float:
                beta, log_s = theta[:-1], theta[-1]
                sd = np.exp(log_s)
                mu = ph @ beta
                a = (z - mu) / sd
                ll = np.where(cens, stats.norm.logsf(a), stats.norm.logpdf(a) - log_s)
                return float(-ll.mean() + 0.5 * alpha * np.sum(beta[1:] ** 2))

            theta0 = np.append(start, np.log(np.std(z - ph @ start)))
            res = optimize.minimize(nll, theta0, method="L-BFGS-B")
            fits[j] = (res.x[:-1], float(np.exp(res.x[-1])))

        def predict(t: np.ndarray) -> np.ndarray:
            out = base(t)
            ph = np.column_stack([np.ones(len(np.atleast_2d(t))), quadratic(t)])
            for j, (beta, sd) in fits.items():
                mu = ph @ beta
                out[:, j] = np.exp(mu + sd**2 / 2) * stats.norm.cdf(
                    (log_cap - mu - sd**2) / sd
                ) + MAX_TRIAL_S * stats.norm.sf((log_cap - mu) / sd)
            return out

        return predict

    idx = [emu.moments_.index(n) for n in NAMES]
    return {
        "as built (log link)": lambda t: emu.means(t)[:, idx],
        "capped trials left out": surface(~capped),
        "settings with a capped trial left out": surface(
            np.repeat(~setting_capped[:, None], len(NAMES), axis=1)
        ),
        "time: logit link on time / cap, penalty 1e-4": surface(logit=1e-4),
        "time: logit link on time / cap, penalty 1e-3": surface(logit=1e-3),
        "cubic log link": surface(terms=cubic),
        "quadratic + each trait's cube": surface(terms=pure_cubes),
        "quadratic + the log speed squared times each trait": surface(terms=speed_cubes),
        "time: two parts, uncapped mean and the cap's chance (linear logit, 1e-3)": two_part(
            1e-3, True
        ),
        "time: two parts, the cap's chance on every term (logit, 1e-2)": two_part(1e-2, False),
        "time: two parts, the cap's chance on every term (logit, 1e-3)": two_part(1e-3, False),
        "time: censored log-normal (Tobit), penalty 1e-3": censored(1e-3),
    }


def own_traits(predict: Predict, fresh: pd.DataFrame, traits: np.ndarray) -> dict[str, Any]:
    """Per group and moment: the fresh people's mean against the surface's mean at their
    own traits, z by the people's SE; the time's gaps in %."""
    per = fresh.groupby(["participant", "condition"])[[n.split(":")[1] for n in NAMES[:3]]].mean()
    people = sorted(fresh["participant"].unique())
    group = fresh.groupby("participant")["group"].first()
    pred = predict(traits)
    z, gaps = [], {}
    for g in truth_profiles(0.7):
        rows = [i for i, p in enumerate(people) if group[p] == g]
        for j, name in enumerate(NAMES):
            c, m = name.split(":")
            v = np.array([per.loc[(people[i], c), m] for i in rows])
            se = v.std(ddof=1) / np.sqrt(len(v))
            z.append(float((pred[rows, j].mean() - v.mean()) / se))
            if m == "completion_time_s":
                gaps[f"{g} {c}"] = round(100 * (pred[rows, j].mean() / v.mean() - 1), 1)
    return {
        "rms_z": round(float(np.sqrt(np.mean(np.square(z)))), 3),
        "of": len(z),
        "time_gap_pct": gaps,
    }


def main(out: str, emulator_path: str, design_path: str, fresh_seed: int = 511) -> None:
    with open(emulator_path, "rb") as f:
        emu = pickle.load(f)
    with open(design_path, "rb") as f:
        d = pickle.load(f)
    x, design, fresh = d["x"], d["design"], d["fresh"]
    truth = truth_profiles(0.7)
    per = fresh["participant"].nunique() // len(truth)
    # the fresh people's traits, drawn as `simulate_people` draws them
    rng = np.random.default_rng([fresh_seed, 0xC4EC])
    people = [draw_traits(g, rng, {g: truth[g]}) for g in truth for _ in range(per)]
    traits = np.array([[getattr(p, t) for t in TRAITS] for p in people])
    results = {}
    for label, predict in variants(emu, x, design).items():
        pop = _compare(lambda g, p=predict: p, fresh, emu)
        time_rows = {
            f"{r['group']} {r['condition']}": round(100 * (r["predicted"] / r["fresh"] - 1), 1)
            for r in pop["rows"]
            if r["measure"] == "completion_time_s" and r["condition"] != "HV-VO"
        }
        results[label] = {
            "own_traits": own_traits(predict, fresh, traits),
            "population": {
                "rms_z": pop["rms_z"],
                "beyond_1_96": pop["beyond_1_96"],
                "of": pop["of"],
                "time_gap_pct": time_rows,
            },
        }
        print(label, json.dumps(results[label]), flush=True)
    report = {
        "data_source": "simulated",
        "command": "python benchmarks/emulator_time_cap.py " + " ".join(sys.argv[1:]),
        "cap_s": MAX_TRIAL_S,
        "capped_design_trials": int((design["completion_time_s"] >= MAX_TRIAL_S - 0.05).sum()),
        "design_trials": len(design),
        "fresh_people_per_group": per,
        "variants": results,
    }
    with open(out, "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3])
