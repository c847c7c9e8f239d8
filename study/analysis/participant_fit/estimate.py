"""Each group's trait distribution from its people's moments: a hierarchical model fitted
by EM, on the emulator.

A person's moments y (the mean over their trials of each log measure and log feature in
each condition) are, by the emulator, f(theta) plus noise of variance
within / (k * defined) + misfit per moment (k trials per condition, `defined` the share
of trials that define a feature, `misfit` the surface's own error, `person_noise_var`).
A group's people have traits theta ~ N(mu, diag(sd^2)).
The fit estimates (mu, sd) of the free traits by expectation-maximisation:

- E-step: each person's posterior mode of their traits under the current (mu, sd), by
  Levenberg-Marquardt on [(y - f(theta)) / noise; (theta - mu) / sd] within the
  emulator's range, and its covariance from the Laplace approximation (J'J)^-1;
- M-step: mu = the mean of the modes; sd^2 = the mean of (mode - mu)^2 plus the
  posterior variances, pooled with `NU0` pseudo-people at the hand-set profile's sd (a
  weak prior: with 4-20 people a group's spread is poorly told by the data, and EM
  would otherwise let it collapse to zero for a trait the data tell little about).

Why people one at a time, not the group's mean and SD of each moment (the method of
simulated moments, which this replaced): a feature that follows two traits (the speed
inside the target branch follows caution and, in HV, the comfort torque) tells the two
apart only within a person, beside another feature that follows one of them (the same
speed in VO). Across a group, the people's spread in the first trait swamps the second.
On a 20/8/8 study with the person-level model, the reaction time and the caution joined
the preferred speed (held-out people, `validate.py`); the steering error, the haptic
threshold, the visual stall time and the comfort torque act in too few of 3 trials per
condition to be told per person, and stay at their priors.

The traits the data tell only weakly (`identifiable`: a group mean's posterior SD above
`IDENTIFIED_RATIO` of the prior SD) are held at their priors by default (`free` without
them): their spread in the group is then added to each person's moment noise
(linearised at the prior means). With `weak` (`study participants fit --weak-traits
shrink`) they are fitted too, under a prior on their group mean: N(the hand-set
profile's mean, `HYPER_SD` of its SD), so the data move such a mean as far as their
information allows. On four simulated 20/8/8 studies with 3 trials per condition, 92 %
of the group means were within 15 % of the truth this way, 86 % fitted freely, 81 % at
the priors (`study bench participants`); why it is not the default: `fit.FitSettings.weak_traits`.

The EM, the batched Levenberg-Marquardt and the Laplace covariances are written here
(about 80 lines of numpy) because the likelihood is on the emulator, where every step
is one matrix product for all people at once; a general package (PyMC, Stan) would
need the emulator re-expressed in its own language and minutes of sampling per
bootstrap replicate. ABC packages (pyabc, elfi) were looked at and not taken: they run
the simulator thousands of times per population (hours at 0.1-0.7 s a trial).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from study.analysis.participant_fit.emulator import MomentEmulator
from study.protocol.traits import TRAIT_BOUNDS, TRAITS, GroupProfile


def expanded_interval(
    boots: np.ndarray, n: int, level: float = 0.95, positive: bool = False
) -> np.ndarray:
    """(2, ...) the 95 % interval of a statistic from its bootstrap replicates over `n`
    people resampled: the percentile interval widened about the replicates' median by
    sqrt(n / (n - 1)) * t(n - 1) / z, Hesterberg's expanded percentile interval (The
    American Statistician 69:371, 2015). A plain percentile interval of a mean over 8-20
    people is too narrow: the resampled people spread by (n - 1) / n of the people's
    variance, and z stands where t belongs (`coverage.py` checks it by simulation).

    `positive`: the statistic is a positive quantity (a mean time, force or trait): the
    interval is widened on the log scale and taken back, so it stays above zero (widened
    on its own scale, a skewed force's lower end over 4 people fell below 0 N) and is
    asymmetric as a positive quantity's is. A replicate at or below 0 leaves the
    ordinary interval."""
    boots = np.asarray(boots, dtype=float)
    if positive and np.all(boots > 0):
        return np.exp(expanded_interval(np.log(boots), n, level))
    tail = 100 * (1 - level) / 2
    low, mid, high = np.percentile(boots, [tail, 50.0, 100 - tail], axis=0)
    if n < 2:
        return np.array([low, high])
    z = stats.norm.ppf(1 - (1 - level) / 2)
    widen = np.sqrt(n / (n - 1)) * stats.t.ppf(1 - (1 - level) / 2, n - 1) / z
    return np.array([mid - widen * (mid - low), mid + widen * (high - mid)])


NU0 = 2.0
"""Pseudo-people at the profile's sd in the M-step's sd (the spread's prior weight)."""
PRIOR_LOG_SD = 0.5
"""How far a group's sd may go from the profile's: within exp(+/- 4 * this) of it."""
HYPER_SD = 1.0
"""A weakly told trait's group mean ~ N(profile mean, this many profile SDs)."""
IDENTIFIED_RATIO = 0.5
"""A trait is identifiable when the data would shrink its group mean's uncertainty to at
most this share of the prior SD (linearised at the priors, the other free traits free
too, in the group where it is worst)."""
DRAWS = 1000
"""Standard normal draws per group for the expected moments."""
EM_STEPS = 300
EM_TOLERANCE = 1e-4
"""Largest change of (mu, log sd), in prior SDs, at which the EM stops."""
LOW = np.array([TRAIT_BOUNDS[t][0] for t in TRAITS])
HIGH = np.array([TRAIT_BOUNDS[t][1] for t in TRAITS])


def prior_arrays(profile: GroupProfile) -> tuple[np.ndarray, np.ndarray]:
    return (
        np.array([getattr(profile, t)[0] for t in TRAITS]),
        np.array([getattr(profile, t)[1] for t in TRAITS]),
    )


def observed_moments(y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean, sd, n) of each moment over a group's people (a feature's over the people it
    is defined for); NaN where fewer than two define it."""
    n = np.isfinite(y).sum(axis=0)
    usable = n >= 2
    mean = np.where(usable, np.nanmean(np.where(usable[None], y, 0.0), axis=0), np.nan)
    sd = np.where(usable, np.nanstd(np.where(usable[None], y, 0.0), axis=0, ddof=1), np.nan)
    return mean, sd, n


def person_noise_var(emulator: MomentEmulator, k: float) -> np.ndarray:
    """Variance of one person's mean of each log-moment about the emulator's prediction:
    the trials' scatter over the k * defined trials that define it, plus the emulator's
    misfit, which does not average away."""
    return emulator.within_var_ / (k * np.maximum(emulator.defined_, 0.1)) + emulator.misfit_var_


def with_fixed_spread(noise_var: np.ndarray, jac_sd: np.ndarray, free: list[int]) -> np.ndarray:
    """A person's moment variance once the traits not in `free` vary at their prior SDs
    too (`jac_sd`: d moment / d trait times the trait's prior SD, linearised)."""
    fixed = [j for j in range(len(TRAITS)) if j not in free]
    return noise_var + (jac_sd[:, fixed] ** 2).sum(axis=1)


def _information(jac: np.ndarray, var: np.ndarray, free: list[int]) -> np.ndarray:
    """One person's Fisher information on the free traits (in prior SDs)."""
    jw = jac[:, free] / np.sqrt(var)[:, None]
    return jw.T @ jw


def identifiable(
    emulator: MomentEmulator,
    profiles: dict[str, GroupProfile],
    sizes: dict[str, np.ndarray],
    ks: dict[str, float],
    held_out: np.ndarray | None = None,
    held_out_k: float | None = None,
    probe_info: dict[str, np.ndarray] | None = None,
) -> tuple[list[int], dict[str, float]]:
    """The traits whose group means the data identify (indices into TRAITS) and each
    trait's ratio: posterior / prior SD of the group mean, linearised at the priors, in
    the group where it is worst, with the other identifiable traits free too.

    Per person, the information I on the free traits (in prior SDs) has the moments' noise
    plus the spread of the traits held at their priors; a person's traits are N(mu, 1),
    so a group of n has the information n * I (I + 1)^-1 on mu, and the posterior
    covariance of mu is (1 + n * I (I + 1)^-1)^-1. Given the error of held-out people's
    estimates from the moments the data have (`held_out`, `validate.py`), each trait's
    ratio is also computed
    from it (I = (prior SD / error)^2) and the larger of the two counts: the slopes can
    promise more than the trials hold. That error is of people with `held_out_k` trials
    per condition (the design's repeats; default: the study's own k): a group's k trials
    tell a trait by the linearised information's ratio at k to that at `held_out_k`
    (the trials' scatter averages away over more trials, the surface's misfit does not),
    so a study with 8 trials per condition is not judged by 2. `probe_info` (group -> per
    trait, a person's mean information from the probes in prior SDs, (prior SD / SE)^2,
    `study.probes.measure.probe_information`) adds to both. Starting from all traits, the worst
    is fixed at its prior until every ratio is below `IDENTIFIED_RATIO` (`sizes`: the
    people defining each moment; a moment fewer than two people define tells nothing)."""
    setup = {}
    for group, profile in profiles.items():
        mu, sd = prior_arrays(profile)
        jac = emulator.jacobian(mu, 0.1 * sd) * sd
        defined = np.asarray(sizes[group]) >= 2
        jac = np.where(defined[:, None], np.nan_to_num(jac), 0.0)
        n = int(np.max(sizes[group]))
        # the same rule on the error of held-out people (`validate.py`), trait by trait
        held = None if held_out is None else (sd / np.maximum(held_out, 1e-12)) ** 2
        noise_held = person_noise_var(emulator, held_out_k or ks[group])
        probe = np.zeros(len(TRAITS)) if probe_info is None else probe_info[group]
        setup[group] = (jac, person_noise_var(emulator, ks[group]), n, held, noise_held, probe)

    def ratios(free: list[int]) -> np.ndarray:
        worst = np.zeros(len(free))
        eye = np.eye(len(free))
        for jac, noise, n, held, noise_held, probe in setup.values():
            task_info = _information(jac, with_fixed_spread(noise, jac, free), free)
            info = task_info + np.diag(probe[free])
            post = np.linalg.inv(eye + n * info @ np.linalg.inv(info + eye))
            linear = np.sqrt(np.clip(np.diag(post), 0.0, None))
            empirical = np.zeros(len(free))
            if held is not None:
                at_held = np.diag(_information(jac, with_fixed_spread(noise_held, jac, free), free))
                # a trait no slope tells keeps the held-out people's information as it is
                more = np.divide(
                    np.diag(task_info), at_held, out=np.ones(len(free)), where=at_held > 0
                )
                per = held[free] * more + probe[free]
                empirical = 1.0 / np.sqrt(1.0 + n * per / (1.0 + per))
            worst = np.maximum(worst, np.maximum(linear, empirical))
        return worst

    free = list(range(len(TRAITS)))
    final: dict[str, float] = {}
    while free:
        r = ratios(free)
        if r.max() < IDENTIFIED_RATIO:
            break
        drop = free[int(np.argmax(r))]
        final[TRAITS[drop]] = float(r.max())
        free.remove(drop)
    final.update({TRAITS[j]: float(r) for j, r in zip(free, ratios(free), strict=True)})
    return sorted(free), final


@dataclass
class GroupFit:
    """One group's fitted trait distribution."""

    mean: np.ndarray
    """(len(TRAITS),) trait means: fitted for the free traits, the prior's for the others."""
    sd: np.ndarray
    cost: float
    """Half the sum of squared standardised residuals of the people's modes."""
    people: np.ndarray
    """(people, len(TRAITS)) each person's posterior mode (the prior's mean where fixed)."""
    success: bool
    """The EM converged within `EM_STEPS`."""


class GroupEstimator:
    """Fits one group's free trait means and SDs to its people's moments.

    Parameters
    ----------
    emulator
        Fitted `MomentEmulator`.
    prior
        The group's hand-set profile: the fixed traits' values and the start.
    free
        Indices into TRAITS of the traits to fit.
    weak
        Those of `free` whose group mean has the prior N(profile mean, `HYPER_SD`
        profile SDs) (the data tell them weakly); the others' means are the data's alone.
    k
        Trials per person and condition (the noise of a person's mean).
    seed
        Of the standard normal draws for the expected moments.
    """

    def __init__(
        self,
        emulator: MomentEmulator,
        prior: GroupProfile,
        free: list[int],
        k: float,
        seed: int = 0,
        weak: list[int] | None = None,
    ) -> None:
        self.emulator, self.free, self.k = emulator, free, k
        self.weak = np.array([j in (weak or []) for j in free], dtype=bool)
        self.mu0, self.sd0 = prior_arrays(prior)
        self.z = np.random.default_rng(seed).standard_normal((DRAWS, len(TRAITS)))
        self.noise_var = person_noise_var(emulator, k)
        jac_sd = np.nan_to_num(emulator.jacobian(self.mu0, 0.1 * self.sd0)) * self.sd0
        self.person_var = with_fixed_spread(self.noise_var, jac_sd, free)
        low, high = emulator.box_
        self.low, self.high = low[free], high[free]
        self.probes: np.ndarray | None = None
        """(people, len(TRAITS), 2): each person's probe estimate and SE per trait (NaN
        where none), set by `fit`."""

    def _probe_rows(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Each person's probe estimates of the free traits and their weights 1 / SE
        (0 where the person has none)."""
        if self.probes is None:
            return np.zeros((n, len(self.free))), np.zeros((n, len(self.free)))
        value, se = self.probes[:, self.free, 0], self.probes[:, self.free, 1]
        told = np.isfinite(value) & np.isfinite(se) & (se > 0)
        return np.where(told, value, 0.0), np.where(told, 1.0 / np.where(told, se, 1.0), 0.0)

    def draws(self, mean: np.ndarray, sd: np.ndarray) -> np.ndarray:
        return np.clip(mean + sd * self.z, LOW, HIGH)

    def expected(self, mean: np.ndarray, sd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The group's expected mean and SD of each log-moment."""
        f = self.emulator.log_moments(self.draws(mean, sd))
        return f.mean(axis=0), np.sqrt(f.var(axis=0) + self.noise_var)

    def _moments(self, theta: np.ndarray) -> np.ndarray:
        full = np.tile(self.mu0, (len(theta), 1))
        full[:, self.free] = theta
        return self.emulator.log_moments(full)

    def posteriors(
        self, y: np.ndarray, mu: np.ndarray, sd: np.ndarray, theta: np.ndarray, steps: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each person's posterior mode of the free traits (people, free), its Laplace
        covariance (people, free, free) and half its squared residuals, after `steps`
        Levenberg-Marquardt steps from `theta` (all people at once)."""
        n, nf = theta.shape
        told = np.isfinite(y)
        yy, w = np.where(told, y, 0.0), np.where(told, 1.0 / np.sqrt(self.person_var), 0.0)
        h = 1e-3 * self.sd0[self.free]
        lam = np.full(n, 1e-2)
        # a probe's estimate p of a trait, SE s: a residual (p - theta) / s (its
        # measurement model, `study.probes`), beside the moments' and the prior's
        pv, pw = self._probe_rows(n)
        probe_jac = -pw[:, :, None] * np.eye(nf)[None]

        def residuals(t: np.ndarray) -> np.ndarray:
            return np.concatenate(
                [(yy - self._moments(t)) * w, (t - mu) / sd, (pv - t) * pw], axis=1
            )

        def jacobian(t: np.ndarray) -> np.ndarray:
            shifted = np.concatenate([t + h[j] * np.eye(nf)[j] for j in range(nf)])
            f0 = self._moments(t)
            f1 = self._moments(shifted).reshape(nf, n, -1)
            jy = -((f1 - f0) / h[:, None, None]).transpose(1, 2, 0) * w[:, :, None]
            prior = np.broadcast_to(np.diag(1.0 / sd), (n, nf, nf))
            return np.concatenate([jy, prior, probe_jac], axis=1)

        r = residuals(theta)
        cost = 0.5 * (r**2).sum(axis=1)
        for _ in range(steps):
            jac = jacobian(theta)
            jtj = jac.transpose(0, 2, 1) @ jac
            g = (jac.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0]
            damp = lam[:, None, None] * np.eye(nf) * np.diagonal(jtj, axis1=1, axis2=2)[:, None]
            step = -np.linalg.solve(jtj + damp, g[:, :, None])[:, :, 0]
            trial = np.clip(theta + step, self.low, self.high)
            r_new = residuals(trial)
            cost_new = 0.5 * (r_new**2).sum(axis=1)
            better = cost_new < cost
            theta = np.where(better[:, None], trial, theta)
            r = np.where(better[:, None], r_new, r)
            cost = np.where(better, cost_new, cost)
            lam = np.where(better, lam / 3, lam * 4)
        jac = jacobian(theta)
        cov = np.linalg.inv(jac.transpose(0, 2, 1) @ jac)
        return theta, cov, cost

    def prior_centre(self, rng: np.random.Generator) -> np.ndarray:
        """The weak traits' prior means drawn from their prior, for one bootstrap
        replicate: resampling the people and drawing the prior's centre, then fitting, is
        randomised maximum likelihood, whose fits are draws from the posterior in a
        linear-Gaussian model. Resampling the people alone would leave out the prior's
        own uncertainty, and a shrunk mean's interval would be too narrow."""
        return self.mu0 + HYPER_SD * self.sd0 * rng.standard_normal(len(self.mu0))

    def start(self) -> np.ndarray:
        return np.concatenate([self.mu0[self.free], np.log(self.sd0[self.free])])

    def fit(
        self,
        y: np.ndarray,
        start: np.ndarray | None = None,
        centre: np.ndarray | None = None,
        probes: np.ndarray | None = None,
    ) -> GroupFit:
        """Fit to `y` (people x moments, log scale; NaN where a feature is undefined);
        `centre` (len(TRAITS)): the weak traits' prior means, default the profile's (a
        bootstrap replicate draws them, `prior_centre`); `probes` (people, len(TRAITS),
        2): the same people's probe estimates and SEs (NaN where none)."""
        self.probes = probes
        nf, n = len(self.free), len(y)
        mean, sd = self.mu0.copy(), self.sd0.copy()
        if nf == 0:
            return GroupFit(mean, sd, 0.0, np.tile(self.mu0, (n, 1)), True)
        x = self.start() if start is None else start.copy()
        mu, s = np.clip(x[:nf], self.low, self.high), np.exp(x[nf:])
        s0 = self.sd0[self.free]
        theta = np.tile(mu, (n, 1))
        converged = False
        m0 = (self.mu0 if centre is None else centre)[self.free]
        for _ in range(EM_STEPS):
            theta, cov, cost = self.posteriors(y, mu, s, theta, steps=3)
            # the group mean: the people's, and for a weak trait with its prior's weight
            data_w, prior_w = n / s**2, np.where(self.weak, 1.0 / (HYPER_SD * s0) ** 2, 0.0)
            mu_new = (theta.mean(axis=0) * data_w + m0 * prior_w) / (data_w + prior_w)
            var = ((theta - mu_new) ** 2 + np.diagonal(cov, axis1=1, axis2=2)).mean(axis=0)
            s_new = np.sqrt((n * var + NU0 * s0**2) / (n + NU0))
            s_new = np.clip(s_new, s0 * np.exp(-4 * PRIOR_LOG_SD), s0 * np.exp(4 * PRIOR_LOG_SD))
            change = max(np.max(np.abs(mu_new - mu) / s0), np.max(np.abs(np.log(s_new / s))))
            mu, s = mu_new, s_new
            if change < EM_TOLERANCE:
                converged = True
                break
        theta, cov, cost = self.posteriors(y, mu, s, theta, steps=10)
        mean[self.free], sd[self.free] = mu, s
        self.x_ = np.concatenate([mu, np.log(s)])
        people = np.tile(self.mu0, (n, 1))
        people[:, self.free] = theta
        return GroupFit(mean, sd, float(cost.sum()), people, converged)
