"""Coverage of the fitted group means' 95 % intervals, by simulation.

An interval that claims 95 % should hold the truth in 95 % of studies. Here `studies`
studies are drawn from a known truth (each group's trait distribution), each person's
moments from the emulator (f(traits) plus the noise of their k trials' mean: the
emulator's trial-noise covariance over k, with the surface's misfit), and each group's
free traits fitted as `study participants fit` fits them (`estimate.GroupEstimator`, the
bootstrap over participants with the weak traits' prior centre drawn, its expanded
percentile interval `estimate.expanded_interval`); a trait's
interval covers when it holds the truth's mean.

The studies are drawn on the emulator, not through the physics: the check is of the
estimator and its bootstrap, given that the emulator describes the people (the
emulator's own agreement with the simulator is `checks.emulator_check`). Through the
physics, 50 studies of 36 people would take hours on this machine.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from study.analysis.participant_fit.emulator import MomentEmulator
from study.analysis.participant_fit.estimate import (
    HIGH,
    LOW,
    GroupEstimator,
    expanded_interval,
    prior_arrays,
)
from study.protocol.traits import PROFILES, TRAITS, GroupProfile
from teleop_core.progress import Progress, no_progress

TARGET = (0.90, 0.98)
"""The share of intervals holding the truth that a calibrated 95 % interval gives, with
the slack 50-100 studies leave."""


def draw_moments(
    emulator: MomentEmulator,
    profile: GroupProfile,
    n: int,
    k: float,
    rng: np.random.Generator,
    probe_se: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """(n, moments) the log moments of `n` people drawn from `profile`, each the mean of
    `k` trials per condition, on the emulator; with `probe_se` (len(TRAITS), NaN where no
    probe tells a trait), also each person's probe estimates as the fit takes them,
    (n, len(TRAITS), 2): their trait plus normal error of that SE (the probes'
    measurement models, `study.probes.measure`), and the SE."""
    mean, sd = prior_arrays(profile)
    theta = np.clip(mean + sd * rng.standard_normal((n, len(TRAITS))), LOW, HIGH)
    cov = emulator.person_noise_cov() / k + np.diag(emulator.misfit_var_)
    noise = rng.multivariate_normal(np.zeros(len(cov)), cov, size=n, method="eigh")
    y = emulator.log_moments(theta) + noise
    if probe_se is None:
        return y, None
    se = np.broadcast_to(np.asarray(probe_se, dtype=float), theta.shape)
    told = np.isfinite(se)
    value = np.where(
        told, theta + np.where(told, se, 0.0) * rng.standard_normal(theta.shape), np.nan
    )
    return y, np.stack([value, np.where(told, se, np.nan)], axis=2)


def typical_probe_se(probed: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per group, each trait's median probe SE over its people (NaN where no person has
    a probe of it), from the fit's (people, len(TRAITS), 2) probe arrays."""
    out = {}
    for group, arrays in probed.items():
        se = arrays[:, :, 1]
        out[group] = np.array(
            [np.median(c[np.isfinite(c)]) if np.isfinite(c).any() else np.nan for c in se.T]
        )
    return out


def coverage(
    emulator: MomentEmulator,
    truth: dict[str, GroupProfile],
    sizes: dict[str, int],
    k: float,
    free: list[int],
    studies: int,
    bootstrap: int,
    seed: int = 0,
    weak: list[int] | None = None,
    progress: Progress = no_progress,
    probe_se: dict[str, np.ndarray] | None = None,
) -> dict[str, Any]:
    """The share of `studies` simulated studies in which each group's fitted mean of each
    free trait has a 95 % bootstrap interval (`bootstrap` replicates) holding the truth;
    `probe_se` (group -> per trait, `typical_probe_se`): every person also answers the
    probes, with those SEs, and the fit takes them as `study participants fit` does."""
    rng = np.random.default_rng([seed, 0xC0FE])
    hits: dict[tuple[str, str], list[bool]] = {}
    errors: dict[tuple[str, str], list[float]] = {}
    for s in range(studies):
        progress("coverage", s, studies)
        for group, n in sizes.items():
            se = None if probe_se is None else probe_se.get(group)
            y, probed = draw_moments(emulator, truth[group], n, k, rng, se)
            est = GroupEstimator(emulator, PROFILES[group], free, k, seed, weak)
            best = est.fit(y, probes=probed)
            start = getattr(est, "x_", None)
            replicates = []
            for _ in range(bootstrap):
                pick = rng.integers(0, n, n)
                fit = est.fit(
                    y[pick], start, est.prior_centre(rng), None if probed is None else probed[pick]
                )
                replicates.append(fit.mean)
            boots = np.array(replicates)
            low, high = expanded_interval(boots, n)
            true = prior_arrays(truth[group])[0]
            spread = boots.std(axis=0, ddof=1)
            for j in free:
                hits.setdefault((group, TRAITS[j]), []).append(bool(low[j] <= true[j] <= high[j]))
                # the estimate's error in bootstrap SDs: a bias shows as a mean away from
                # 0, a too narrow bootstrap as a spread above 1
                errors.setdefault((group, TRAITS[j]), []).append(
                    float((best.mean[j] - true[j]) / max(spread[j], 1e-12))
                )
    progress("coverage", studies, studies)
    per = [
        {
            "group": g,
            "trait": t,
            "coverage": float(np.mean(v)),
            "studies": len(v),
            "error_mean_boot_sds": float(np.mean(errors[(g, t)])),
            "error_sd_boot_sds": float(np.std(errors[(g, t)], ddof=1)) if len(v) > 1 else None,
        }
        for (g, t), v in hits.items()
    ]
    every = [h for v in hits.values() for h in v]
    share = float(np.mean(every)) if every else float("nan")
    return {
        "studies": studies,
        "bootstrap": bootstrap,
        "coverage": share,
        "intervals": len(every),
        "target": list(TARGET),
        "met": bool(TARGET[0] <= share <= TARGET[1]),
        "per_trait": per,
        "note": "studies drawn on the emulator from the truth (the people's moments with "
        "the trial noise of k trials), each group's free traits fitted with the fit's "
        "bootstrap; coverage: the share of 95 % intervals of a group mean holding the truth",
    }
