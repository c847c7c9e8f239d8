"""The method of simulated moments on the emulator: each group's trait distribution.

A person's moments y (the mean over their trials of each log measure in each condition)
are, by the emulator, f(theta) plus trial noise of covariance Sigma_e / k (k trials per
condition). A group's traits are theta = clip(mu + sd * z): normal, clipped into the
traits' ranges as `draw_traits` draws them. For given (mu, sd), the group's expected
mean and standard deviation of each moment are computed over a fixed set of standard
normal draws z (common random numbers, so the objective is smooth in the parameters):

    m(mu, sd) = mean_z f(theta),   s(mu, sd)^2 = var_z f(theta) + diag(Sigma_e) / k

and (mu, sd) of the free traits minimise, by `scipy.optimize.least_squares` within the
traits' bounds, the standardised distances to the observed group mean and SD of each
moment (their standard errors from the data: sd / sqrt(n) and sd / sqrt(2 (n - 1))),
plus a weak prior on log(sd) (centred on the hand-set profile's sd, `PRIOR_LOG_SD`):
with 4-20 people a group's spread is poorly told by the data, and the penalty keeps it
from collapsing to zero or running away (a MAP estimate for the spreads, plain MSM for
the means). The traits the data cannot identify (`identifiable`) stay at their priors.

ABC packages (pyabc, elfi) were looked at and not taken: they run the simulator
thousands of times per population (hours at 0.1-0.7 s a trial), and on the emulator the
moment objective is smooth, so a least-squares solver finds its minimum in milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from study.analysis.participant_fit.emulator import MomentEmulator
from study.protocol.participants import TRAIT_BOUNDS, TRAITS, GroupProfile

PRIOR_LOG_SD = 0.5
"""SD of the prior on log(trait sd / profile sd): a factor of 1.65 either way is 1 SD."""
IDENTIFIED_RATIO = 0.5
"""A trait is identifiable when the data would shrink its mean's uncertainty to at most
this share of the prior SD (linearised, with the others at their priors)."""
DRAWS = 1000
"""Standard normal draws per group for the expected moments."""
LOW = np.array([TRAIT_BOUNDS[t][0] for t in TRAITS])
HIGH = np.array([TRAIT_BOUNDS[t][1] for t in TRAITS])


def prior_arrays(profile: GroupProfile) -> tuple[np.ndarray, np.ndarray]:
    return (
        np.array([getattr(profile, t)[0] for t in TRAITS]),
        np.array([getattr(profile, t)[1] for t in TRAITS]),
    )


def observed_moments(y: np.ndarray, noise_sd: np.ndarray, k: float) -> tuple[np.ndarray, ...]:
    """(mean, sd, se of the mean, se of the sd) of each moment over a group's people."""
    n = len(y)
    mean, sd = y.mean(axis=0), y.std(axis=0, ddof=1)
    floor = 0.5 * noise_sd / np.sqrt(k)
    spread = np.maximum(sd, floor)
    return mean, sd, spread / np.sqrt(n), spread / np.sqrt(2 * (n - 1))


def identifiable(
    emulator: MomentEmulator,
    profiles: dict[str, GroupProfile],
    spreads: dict[str, np.ndarray],
    sizes: dict[str, int],
) -> tuple[list[int], dict[str, float]]:
    """The traits whose group means the moments identify (indices into TRAITS), chosen
    greedily, and each trait's ratio (posterior / prior SD of its mean, linearised at
    the priors, in the group where it is worst) when the others chosen are free too.

    J[m, j] = d E[moment m] / d mu_j * prior sd_j / se_m, with se_m the sampling error of
    the group mean of moment m; the posterior covariance in prior-SD units is
    (J_S' J_S + I)^-1 over the free set S."""
    jacobians = {}
    for group, profile in profiles.items():
        mu, sd = prior_arrays(profile)
        se = spreads[group] / np.sqrt(sizes[group])
        jacobians[group] = emulator.jacobian(mu, 0.1 * sd) * sd / se[:, None]

    def ratios(free: list[int]) -> np.ndarray:
        worst = np.zeros(len(free))
        for jac in jacobians.values():
            js = jac[:, free]
            cov = np.linalg.inv(js.T @ js + np.eye(len(free)))
            worst = np.maximum(worst, np.sqrt(np.diag(cov)))
        return worst

    free: list[int] = []
    while True:
        best, best_ratio = None, IDENTIFIED_RATIO
        for j in range(len(TRAITS)):
            if j in free:
                continue
            r = ratios([*free, j])
            if r.max() < best_ratio:
                best, best_ratio = j, r.max()
        if best is None:
            break
        free.append(best)
    final = {TRAITS[j]: float(r) for j, r in zip(free, ratios(free), strict=True)} if free else {}
    for j, trait in enumerate(TRAITS):
        if j not in free:
            final[trait] = float(ratios([*free, j])[-1])
    return sorted(free), final


@dataclass
class GroupFit:
    """One group's fitted trait distribution."""

    mean: np.ndarray
    """(len(TRAITS),) trait means: fitted for the free traits, the prior's for the others."""
    sd: np.ndarray
    cost: float
    """Half the sum of squared standardised residuals at the optimum."""
    residuals: np.ndarray
    success: bool


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
    k
        Trials per person and condition (the noise of a person's mean).
    seed
        Of the standard normal draws.
    """

    def __init__(
        self,
        emulator: MomentEmulator,
        prior: GroupProfile,
        free: list[int],
        k: float,
        seed: int = 0,
    ) -> None:
        self.emulator, self.free, self.k = emulator, free, k
        self.mu0, self.sd0 = prior_arrays(prior)
        self.z = np.random.default_rng(seed).standard_normal((DRAWS, len(TRAITS)))
        self.noise_var = np.diag(emulator.noise_cov_) / k

    def params(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mean, sd) over all traits from the free parameters p = [mu/sd0, log sd]."""
        nf = len(self.free)
        mean, sd = self.mu0.copy(), self.sd0.copy()
        mean[self.free] = p[:nf] * self.sd0[self.free]
        sd[self.free] = np.exp(p[nf:])
        return mean, sd

    def draws(self, mean: np.ndarray, sd: np.ndarray) -> np.ndarray:
        return np.clip(mean + sd * self.z, LOW, HIGH)

    def expected(self, mean: np.ndarray, sd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The group's expected mean and SD of each log-moment."""
        f = self.emulator.log_moments(self.draws(mean, sd))
        return f.mean(axis=0), np.sqrt(f.var(axis=0) + self.noise_var)

    def residuals(self, p: np.ndarray, target: tuple[np.ndarray, ...]) -> np.ndarray:
        mean_obs, sd_obs, se_mean, se_sd = target
        mean, sd = self.params(p)
        m, s = self.expected(mean, sd)
        prior = (np.log(sd[self.free]) - np.log(self.sd0[self.free])) / PRIOR_LOG_SD
        return np.concatenate([(mean_obs - m) / se_mean, (sd_obs - s) / se_sd, prior])

    def start(self) -> np.ndarray:
        return np.concatenate(
            [self.mu0[self.free] / self.sd0[self.free], np.log(self.sd0[self.free])]
        )

    def fit(self, y: np.ndarray, start: np.ndarray | None = None) -> GroupFit:
        """Fit to `y` (people x moments, log scale)."""
        target = observed_moments(y, np.sqrt(np.diag(self.emulator.noise_cov_)), self.k)
        nf = len(self.free)
        s0 = self.sd0[self.free]
        box_low, box_high = self.emulator.box_
        low = np.concatenate([box_low[self.free] / s0, np.log(s0) - 4 * PRIOR_LOG_SD])
        high = np.concatenate([box_high[self.free] / s0, np.log(s0) + 4 * PRIOR_LOG_SD])
        x0 = np.clip(self.start() if start is None else start, low + 1e-9, high - 1e-9)
        if nf == 0:
            mean, sd = self.params(x0)
            r = self.residuals(x0, target)
            return GroupFit(mean, sd, 0.5 * float(r @ r), r, True)
        out = least_squares(
            self.residuals, x0, bounds=(low, high), args=(target,), x_scale=1.0, diff_step=1e-4
        )
        mean, sd = self.params(out.x)
        self.x_ = out.x
        return GroupFit(mean, sd, float(out.cost), out.fun, bool(out.success))
