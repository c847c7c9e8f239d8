"""The emulator: a task's per-person moments as a smooth function of the traits.

Running the physics for every candidate trait distribution is what makes
simulation-based inference slow (0.1-0.7 s per LCCA trial). Instead, a designed set of
trait settings (a Latin hypercube over the priors' range, `scipy.stats.qmc`) is
simulated once with common random numbers (`simulate.py`), and each moment, the log of
a measure or of a behavioural feature of the samples (`Task.fit_features`: the advance
speed, how early the approach slows, the aim, the time before backing off, ...) in a
condition, is regressed on the traits: a quadratic response surface in the log traits
(the caution, a share in [0, 1], as it is), scikit-learn's `PolynomialFeatures` +
`RidgeCV` on the standardised traits, each moment's ridge penalty chosen by its own
leave-one-out (generalised) cross-validation.

Why logs and a penalty per moment (held-out people simulated apart from the design,
`study bench participants`): with raw traits and one penalty (1) for every moment, a noisy feature's
36 quadratic terms followed the design's luck, and the aim error's surface was off by
+0.20 in log at steering errors of 0.2-0.28 rad (its noise SE 0.09); the group fits
then put the novices' and experts' steering error 15-30 % high. With log traits (the
features follow the traits by ratios) and the penalty per moment, the offset fell to
+0.12, and recovering four simulated 20/8/8 studies put 92 % of the group means within
15 % of the truth (81 % before). What the
regression leaves is the trial-to-trial noise (plus the surface's misfit, so the noise
is not understated); its covariance across moments is kept, since one trial's time and
forces move together.

The means the report compares (the emulator check: a group's mean peak force is a mean
of forces, not of logs) are on the measures' own scale, from a surface of their own: a
log-link regression of each measure itself on the same terms (scikit-learn's
`PoissonRegressor` objective, solved here, `poisson_ridge`: quasi-Poisson, whose
estimating equations make the fitted mean match the trials' mean wherever the terms
reach, whatever the noise's distribution), with a small penalty (`MEAN_ALPHA`).
Why not exp(log surface) times one smearing factor (Duan's mean of exp(residual), which
the features keep): that factor is a single constant, and the measures' residual is
neither lognormal nor of one spread across the traits. A peak distal force is a
mixture (a low level without contact, spikes with it, a few trials near 0 N far out
in log), and the share of spikes follows the traits; a completion time has a cap (a
give-up at the trial's limit) reached in the slow corners of the design only, so a
group's own smearing factor differs from the design's average (against fresh simulated
people, `benchmarks/emulator_bias.py`).

The measures alone (a trial's time and peak forces) identify little more than the
preferred speed: every trait slows a trial or raises its peaks a little, and with a
handful of people per group their effects cannot be told apart. The features separate
them, as a rater watching the recordings would.

`fit` returns self and the fitted values end in `_`, as in scikit-learn. The moment
names are `CONDITION:measure` (`VO:completion_time_s`), `CONDITION:feature` after them.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from functools import lru_cache
from typing import NamedTuple

import numpy as np
import pandas as pd
from scipy import special, stats
from scipy.stats import qmc
from sklearn.linear_model import RidgeCV
from sklearn.preprocessing import PolynomialFeatures, StandardScaler

from study.protocol.design import KNOWN_CONDITIONS
from study.protocol.traits import PROFILES, TRAIT_BOUNDS, TRAITS, GroupProfile

LOG_FLOOR = 1e-3
"""Smallest value taken before a log (a peak force of 0 N reads as 1 mN)."""
FEATURE_FLOOR = 1e-12
"""The same for a fit feature (positive by definition, some of the order of 1e-4)."""
DESIGN_SDS = 2.5
"""The design spans every prior group mean +/- this many prior SDs (within the bounds)."""
LINEAR_TRAITS = ("caution",)
"""Traits the surface takes as they are (a share that may be 0); the others by their log."""
_LOGGED = np.array([t not in LINEAR_TRAITS for t in TRAITS])
ALPHAS = tuple(np.logspace(-1, 4, 21))
"""The ridge penalties each moment's cross-validation chooses from."""
MEAN_ALPHA = 1e-3
"""The mean surface's penalty (scikit-learn's `PoissonRegressor.alpha`, on the measure
divided by its mean): a small one, for a well-posed Newton step only. Chosen against
fresh simulated people (`benchmarks/emulator_bias.py`): penalties a cross-validation
of the deviance over the design's whole box prefers draw the groups' means towards the
box's."""
DESIGN_REFITS = 20
"""Refits of the measures' mean surfaces to bootstrap resamples of the design's settings
(`MomentEmulator.refitted_means`): the emulator's own noise from its finite design."""


class CanonicalLink(NamedTuple):
    """A generalised linear model's canonical link, as functions of the linear predictor
    eta: the cumulant b(eta) (the log-likelihood is y * eta - b(eta)), the mean b'(eta)
    (the inverse link), and the variance b''(eta) as a function of that mean; `start`
    is the link itself, eta of a mean (kept inside the mean's range), for a constant
    model's intercept."""

    cumulant: Callable[[np.ndarray], np.ndarray]
    mean: Callable[[np.ndarray], np.ndarray]
    variance: Callable[[np.ndarray], np.ndarray]
    start: Callable[[float], float]


LOG_LINK = CanonicalLink(
    cumulant=np.exp,
    mean=np.exp,
    variance=lambda mu: mu,
    start=lambda m: float(np.log(max(m, 1e-12))),
)
"""Poisson's: mean exp(eta), variance the mean."""
LOGIT_LINK = CanonicalLink(
    cumulant=lambda eta: np.logaddexp(0.0, eta),
    mean=lambda eta: 1 / (1 + np.exp(-eta)),
    variance=lambda mu: mu * (1 - mu),
    start=lambda m: float(special.logit(min(max(m, 1e-6), 1 - 1e-6))),
)
"""Bernoulli's (also a fractional logit's, y in [0, 1]): mean 1 / (1 + exp(-eta)),
variance mean (1 - mean)."""


def glm_ridge(
    phi: np.ndarray,
    y: np.ndarray,
    w: np.ndarray,
    alpha: float,
    link: CanonicalLink,
    steps: int = 50,
) -> tuple[np.ndarray, float]:
    """(coef, intercept) minimising mean_w(cumulant(eta) - y * eta) + alpha / 2 *
    |coef|^2, eta = intercept + phi @ coef (the intercept unpenalised; `w` normalised to
    mean 1): a generalised linear model of `y` on `phi` with a canonical `link`, whose
    objective is the deviance / 2 up to a constant in the coefficients. Newton's method
    from the constant model (the intercept the link of y's weighted mean), each step
    halved until the objective does not rise, stopped when a step lowers it by no more
    than 1e-12 of its size or after `steps`. With a canonical link the gradient is
    X'w(mean - y) / n and the Hessian X' diag(w variance(mean)) X / n (plus the
    penalty)."""
    w = w / w.mean()
    n, p = phi.shape
    x = np.column_stack([np.ones(n), phi])
    pen = np.full(p + 1, alpha)
    pen[0] = 0.0
    beta = np.zeros(p + 1)
    beta[0] = link.start(float(np.average(y, weights=w)))

    def objective(b: np.ndarray) -> float:
        eta = x @ b
        return float(np.mean(w * (link.cumulant(eta) - y * eta)) + 0.5 * np.sum(pen * b * b))

    current = objective(beta)
    for _ in range(steps):
        mu = link.mean(x @ beta)
        grad = x.T @ (w * (mu - y)) / n + pen * beta
        hess = (x.T * (w * link.variance(mu))) @ x / n + np.diag(pen)
        step = np.linalg.solve(hess, grad)
        t = 1.0
        while t > 1e-8:
            trial = objective(beta - t * step)
            if trial <= current:
                break
            t /= 2
        beta, change = beta - t * step, current - trial
        current = trial
        if abs(change) <= 1e-12 * max(abs(current), 1.0):
            break
    return beta[1:], float(beta[0])


def poisson_ridge(
    phi: np.ndarray, y: np.ndarray, w: np.ndarray, alpha: float, steps: int = 50
) -> tuple[np.ndarray, float]:
    """(coef, intercept) minimising mean_w(deviance) / 2 + alpha / 2 * |coef|^2 of a
    log-link Poisson model of `y` on `phi` (the intercept unpenalised; `w` normalised to
    mean 1): scikit-learn's `PoissonRegressor(alpha)` objective, by `glm_ridge`.
    Written here because scikit-learn's solvers spend most of a fit this small on their
    setup and checks, a hundred times this loop's time (six fits per emulator, more in
    the local surfaces and benches); the tests hold it to scikit-learn's answer."""
    return glm_ridge(phi, y, w, alpha, LOG_LINK, steps)


def fit_mean_surface(
    phi: np.ndarray, y: np.ndarray, w: np.ndarray, alpha: float = MEAN_ALPHA
) -> tuple[np.ndarray, float, float]:
    """A log-link (quasi-Poisson) regression of `y` on the terms `phi` (without the
    constant), weights `w`, penalty `alpha` on y / scale. Returns its (coef, intercept)
    for y / scale and the scale (the weighted mean of y)."""
    scale = float(np.average(y, weights=w))
    coef, intercept = poisson_ridge(phi, y / scale, w, alpha)
    return coef, intercept, scale


def surface_traits(traits: np.ndarray) -> np.ndarray:
    """The traits as the surface takes them: the log of each, but `LINEAR_TRAITS`."""
    out = np.array(traits, dtype=float, copy=True)
    out[:, _LOGGED] = np.log(out[:, _LOGGED])
    return out


def moment_names(measures: Sequence[str]) -> list[str]:
    return [f"{c}:{m}" for c in KNOWN_CONDITIONS for m in measures]


def log_moment(values: np.ndarray | pd.Series, floor: float = LOG_FLOOR) -> np.ndarray:
    return np.log(np.maximum(np.asarray(values, dtype=float), floor))


def floor(column: str, measures: Sequence[str]) -> float:
    """The floor before the log of a measure (`LOG_FLOOR`) or a feature (`FEATURE_FLOOR`)
    column, or of a moment named `CONDITION:column`."""
    return LOG_FLOOR if column.split(":", 1)[-1] in measures else FEATURE_FLOOR


def design_box(profiles: dict[str, GroupProfile] = PROFILES) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of each trait over which the emulator is built."""
    low, high = [], []
    for trait in TRAITS:
        ms = [getattr(p, trait) for p in profiles.values()]
        lo, hi = TRAIT_BOUNDS[trait]
        low.append(max(min(m - DESIGN_SDS * s for m, s in ms), lo))
        high.append(min(max(m + DESIGN_SDS * s for m, s in ms), hi))
    return np.array(low), np.array(high)


def design_settings(n: int, seed: int, box: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """`n` trait settings, (n, len(TRAITS)): a Latin hypercube over `box`."""
    unit = qmc.LatinHypercube(d=len(TRAITS), seed=seed).random(n)
    return qmc.scale(unit, box[0], box[1])


LOCAL_WIDEN = 2.5
"""A group's share of the design, and its weight in the group's local surface, follow
the group's prior with its SDs widened this many times."""


def group_design_settings(
    n: int, seed: int, profiles: dict[str, GroupProfile] = PROFILES, widen: float = LOCAL_WIDEN
) -> tuple[np.ndarray, np.ndarray]:
    """`n` trait settings split evenly across the groups, each group's a Latin hypercube
    of normal quantiles about its prior mean with the SDs widened `widen` times (within
    `design_box`); and the group index of each setting."""
    low, high = design_box(profiles)
    parts, owner = [], []
    for g, profile in enumerate(profiles.values()):
        size = n // len(profiles) + (g < n % len(profiles))
        unit = qmc.LatinHypercube(d=len(TRAITS), seed=np.random.default_rng([seed, g])).random(size)
        mean = np.array([getattr(profile, t)[0] for t in TRAITS])
        sd = np.array([getattr(profile, t)[1] for t in TRAITS])
        parts.append(np.clip(mean + widen * sd * stats.norm.ppf(unit), low, high))
        owner += [g] * size
    return np.concatenate(parts), np.array(owner)


def trial_matrix(trials: pd.DataFrame, columns: Sequence[str]) -> pd.DataFrame:
    """One row per (setting, repeat): every condition's `columns` (measures, features)
    side by side, named `moment_names(columns)`."""
    wide = trials.pivot_table(
        index=["setting", "repeat"],
        columns="condition",
        values=list(columns),
        aggfunc="first",
        dropna=False,
    )
    return pd.DataFrame({n: wide[tuple(reversed(n.split(":", 1)))] for n in moment_names(columns)})


MIN_DEFINED = 20
"""Fewest design trials a feature must be defined in to be emulated (else it is dropped)."""


def _weighted_mean(values: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Column means of `values` (rows, columns) weighted by `w` (rows,) or (rows, 1),
    over the rows where a column is defined; NaN where none is."""
    w = np.broadcast_to(np.reshape(w, (len(values), -1)), values.shape)
    ok = np.isfinite(values) & (w > 0)
    total = np.where(ok, w, 0.0).sum(axis=0)
    summed = np.where(ok, values * w, 0.0).sum(axis=0)
    return np.divide(summed, total, out=np.full(values.shape[1], np.nan), where=total > 0)


def _weighted_variance(values: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Column variances (about the weighted mean, no correction) weighted by `w`."""
    return _weighted_mean((values - _weighted_mean(values, w)) ** 2, w)


def _effective(weights: np.ndarray) -> float:
    """Kish's effective number of settings of `weights`."""
    return float(weights.sum() ** 2 / (weights**2).sum())


def polynomial_terms(z: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """The monomials `powers` (terms, columns; `PolynomialFeatures.powers_`) of `z`
    (rows, columns): `np.prod(z[:, None, :] ** powers[None], axis=2)`, bit for bit. Up
    to degree 2 a term is a product of at most two factors, the others 1 (exact), so it
    is one product of two gathered columns of [1, z, z ** 2] (the square by numpy's
    `power`, as there), without the pow of every term's every column."""
    plan = _term_plan(powers.tobytes(), powers.shape, powers.dtype.str)
    if plan is None:
        return np.prod(z[:, None, :] ** powers[None], axis=2)
    ext = np.concatenate(
        [np.ones((len(z), 1)), z, z ** np.full(z.shape, 2, dtype=powers.dtype)], axis=1
    )
    return ext[:, plan[0]] * ext[:, plan[1]]


@lru_cache(maxsize=16)
def _term_plan(
    raw: bytes, shape: tuple[int, ...], dtype: str
) -> tuple[np.ndarray, np.ndarray] | None:
    """For `polynomial_terms`: each term's two columns of [1, z, z ** 2] (column 0 is
    1, 1 + j is z_j, 1 + n + j is z_j ** 2), or None above degree 2."""
    powers = np.frombuffer(raw, dtype=dtype).reshape(shape)
    if powers.sum(axis=1).max(initial=0) > 2:
        return None
    n = shape[1]
    first, second = np.zeros(len(powers), int), np.zeros(len(powers), int)
    for k, p in enumerate(powers):
        used = np.flatnonzero(p)
        if len(used) == 2:
            first[k], second[k] = 1 + used[0], 1 + used[1]
        elif len(used) == 1:
            first[k] = 1 + used[0] + (n if p[used[0]] == 2 else 0)
    return first, second


class MomentEmulator:
    """Log-moments and measure means of one person as functions of the traits.

    The moments are the task's measures and, where the trials have samples, its fit
    features (`Task.fit_features`) in each condition. A feature may be undefined in a
    trial (a backing-off that did not happen): each moment's surface is fitted on the
    design trials where it is defined, over one shared set of polynomial terms (so the
    prediction stays one matrix product), and `defined_` keeps the share of trials that
    define it (a person's mean of it rests on that share of their trials). A feature
    defined in fewer than `MIN_DEFINED` design trials of every condition is dropped;
    `dropped_features_` keeps it with the most design trials of one condition that
    define it (0: the design's trials do not hold it), so the report can say why.

    Parameters
    ----------
    degree
        Of the polynomial response surface (2: quadratic, with interactions).
    alphas
        Ridge penalties on the standardised terms, one chosen per moment by
        leave-one-out cross-validation: a precise moment (the advance speed) keeps its
        curvature, a noisy one (the aim error) its main slopes only.
    mean_surface
        Fit the measures' log-link mean surface (`means`); the held-out validation's
        fold emulators, which use the log surface only, go without it.
    """

    # set after `fit`, and absent until then: by `local` and by the held-out validation
    local_: dict[str, float]
    """`local`'s widening of the prior and the effective number of settings."""
    design_: tuple[np.ndarray, pd.DataFrame, int]
    """The design's settings, trials and repeats (`validate.attach`)."""
    held_out_error_: np.ndarray
    """The held-out error of each trait (`validate.attach`)."""

    def __init__(
        self, degree: int = 2, alphas: Sequence[float] = ALPHAS, mean_surface: bool = True
    ) -> None:
        self.degree = degree
        self.alphas = tuple(alphas)
        self.mean_surface = mean_surface

    def fit(
        self,
        settings: np.ndarray,
        trials: pd.DataFrame,
        measures: Sequence[str],
        features: Sequence[str] = (),
        weights: np.ndarray | None = None,
    ) -> MomentEmulator:
        """`settings` (n, len(TRAITS)); `trials` from `simulate_settings` over them;
        `weights` (n,): each setting's weight in the surface and in the residual's
        statistics (default equal; `local` weights them by a group's prior)."""
        self.measures_ = list(measures)
        self.training_ = (settings, trials, tuple(features))
        self.setting_weights_ = None if weights is None else np.asarray(weights, float)
        asked = list(features)
        features = [f for f in asked if f in trials and trials[f].notna().any()]
        names = [*moment_names(measures), *moment_names(features)]
        wide = trial_matrix(trials, [*measures, *features])[names]
        x = settings[wide.index.get_level_values("setting")]
        y = np.column_stack([log_moment(wide[n], floor(n, measures)) for n in wide.columns])
        defined = np.isfinite(y).sum(axis=0)
        keep = defined >= MIN_DEFINED
        keep[: len(self.measures_) * len(KNOWN_CONDITIONS)] = True
        self.moments_ = [n for n, k in zip(wide.columns, keep, strict=True) if k]
        self.features_ = [f for f in features if any(n.endswith(f":{f}") for n in self.moments_)]
        by_name = dict(zip(wide.columns, defined.tolist(), strict=True))
        self.dropped_features_ = {
            f: int(max(by_name.get(f"{c}:{f}", 0) for c in KNOWN_CONDITIONS))
            for f in asked
            if f not in self.features_
        }
        y = y[:, keep]
        setting_w = np.ones(len(settings)) if weights is None else np.asarray(weights, float)
        w = setting_w[wide.index.get_level_values("setting")]
        w = w / w.mean()
        scaler = StandardScaler().fit(surface_traits(x))
        self.centre_, self.scale_ = scaler.mean_, scaler.scale_
        self.powers_ = PolynomialFeatures(self.degree).fit(x).powers_
        phi = self.terms(x)
        self.coef_ = np.zeros((phi.shape[1], y.shape[1]))
        self.intercept_ = np.zeros(y.shape[1])
        self.alpha_ = np.zeros(y.shape[1])
        resid = np.full_like(y, np.nan)
        for j in range(y.shape[1]):
            ok = np.isfinite(y[:, j])
            ridge = RidgeCV(alphas=list(self.alphas)).fit(phi[ok], y[ok, j], sample_weight=w[ok])
            self.coef_[:, j], self.intercept_[j] = ridge.coef_, ridge.intercept_
            self.alpha_[j] = ridge.alpha_
            resid[ok, j] = y[ok, j] - ridge.predict(phi[ok])
        self.defined_ = _weighted_mean(np.isfinite(y).astype(float), w)
        self._residual_statistics(resid, w, wide.index.get_level_values("setting"))
        self.mean_moments_: list[str] = []
        if getattr(self, "mean_surface", True):
            self._fit_means(wide, phi, w)
        total = _weighted_variance(y, w)
        r2 = 1 - _weighted_variance(resid, w) / np.where(total > 0, total, 1)
        self.r2_ = dict(zip(self.moments_, r2, strict=True))
        self.n_settings_, self.n_trials_ = len(settings), len(trials)
        self.box_ = (settings.min(axis=0), settings.max(axis=0))
        return self

    def _fit_means(self, wide: pd.DataFrame, phi: np.ndarray, w: np.ndarray) -> None:
        """The measures' mean surfaces (`fit_mean_surface`) on the terms without the
        constant, over the trials where the measure is defined."""
        self.mean_moments_ = moment_names(self.measures_)
        coef, intercept, scale = [], [], []
        for name in self.mean_moments_:
            y = wide[name].to_numpy(float)
            ok = np.isfinite(y)
            c, i, sc = fit_mean_surface(phi[ok, 1:], np.maximum(y[ok], 0.0), w[ok])
            coef.append(c)
            intercept.append(i)
            scale.append(sc)
        self.mean_coef_ = np.column_stack(coef)
        self.mean_intercept_ = np.array(intercept)
        self.mean_scale_ = np.array(scale)

    def refitted_means(
        self, traits: np.ndarray, refits: int = DESIGN_REFITS, seed: int = 0
    ) -> np.ndarray:
        """The measures' mean surfaces (`mean_moments_`) at `traits` (n, len(TRAITS)) as
        `refits` surfaces refitted to bootstrap resamples of the design's settings (each
        setting with its trials, drawn with replacement) would predict them ->
        (refits, n, len(mean_moments_)): their spread is the emulator's own noise, which
        a comparison with simulated people must count beside the people's. A resample is
        the design's trials weighted by how often their setting was drawn (a weight of 2
        is the trial twice); the terms and the penalty are the emulator's. Refits only,
        no simulation; kept once made (per `refits`, `seed`)."""
        names = getattr(self, "mean_moments_", [])
        if not names:
            return np.zeros((refits, len(np.atleast_2d(traits)), 0))
        cache = self.__dict__.setdefault("_refits", {})
        if (refits, seed) not in cache:
            settings, trials, _ = self.training_
            wide = trial_matrix(trials, self.measures_)[names]
            setting = wide.index.get_level_values("setting").to_numpy()
            base = getattr(self, "setting_weights_", None)
            base = np.ones(len(settings)) if base is None else base
            phi = self.terms(settings[setting])[:, 1:]
            y = wide.to_numpy(float)
            rng = np.random.default_rng([seed, 0xDE5])
            fits = []
            for _ in range(refits):
                drawn = np.bincount(
                    rng.integers(0, len(settings), len(settings)), minlength=len(settings)
                )
                w = (base * drawn)[setting]
                coef, intercept, scale = [], [], []
                for j in range(len(names)):
                    ok = np.isfinite(y[:, j]) & (w > 0)
                    c, i, sc = fit_mean_surface(phi[ok], np.maximum(y[ok, j], 0.0), w[ok])
                    coef.append(c)
                    intercept.append(i)
                    scale.append(sc)
                fits.append((np.column_stack(coef), np.array(intercept), np.array(scale)))
            cache[(refits, seed)] = fits
        terms = self.terms(traits)[:, 1:]
        return np.stack([np.exp(terms @ c + i) * sc for c, i, sc in cache[(refits, seed)]])

    def _residual_statistics(self, resid: np.ndarray, w: np.ndarray, setting: pd.Index) -> None:
        """The trials' noise about the surface, weighted by `w` (each trial's, mean 1)."""
        # the surface's own error at a setting does not average away over a person's
        # trials: split the residual into the trials' scatter about their setting's mean
        # (pooled within settings) and the spread of those means beyond what the scatter
        # explains (the misfit)
        # (with one trial per setting the two cannot be told apart: all is scatter)
        scaled = resid * np.sqrt(w)[:, None]
        by_setting = pd.DataFrame(resid).groupby(setting)
        setting_w = pd.Series(w).groupby(setting).mean().to_numpy()[:, None]
        within = _weighted_mean(by_setting.var(ddof=1).to_numpy(), setting_w)
        total_var = np.nan_to_num(_weighted_variance(resid, w))
        self.within_var_ = np.maximum(np.where(np.isfinite(within), within, total_var), 1e-10)
        per = by_setting.count().mean().to_numpy()
        means = by_setting.mean().to_numpy()
        n_means = np.isfinite(means).sum(axis=0)
        spread = _weighted_variance(means, setting_w) * n_means / np.maximum(n_means - 1, 1)
        between = spread - self.within_var_ / per
        between = np.clip(np.nan_to_num(between), 0.0, None)
        self.misfit_var_ = np.where(np.isfinite(within), between, 0.0)
        self.smearing_ = _weighted_mean(np.exp(resid), w)
        # noise of one trial's log-moments (and the surface's misfit), across moments:
        # pairwise where features are undefined, then made positive definite
        cov = pd.DataFrame(scaled).cov(min_periods=MIN_DEFINED // 2).fillna(0.0).to_numpy()
        ev, v = np.linalg.eigh(cov)
        self.noise_cov_ = np.atleast_2d((v * np.maximum(ev, 1e-6 * ev.max())) @ v.T)

    def local(self, profile: GroupProfile, widen: float = LOCAL_WIDEN) -> MomentEmulator:
        """The same emulator refitted to its design with each setting weighted by the
        group's prior density (`profile`, its SDs widened `widen` times): a surface that
        fits the group's own range of traits, where a global quadratic surface bends to
        fit the other groups' too. The design's range (`box_`) and held-out errors are
        kept."""
        settings, trials, features = self.training_
        mean = np.array([getattr(profile, t)[0] for t in TRAITS])
        sd = np.array([getattr(profile, t)[1] for t in TRAITS])
        log_w = stats.norm.logpdf((settings - mean) / (widen * sd)).sum(axis=1)
        weights = np.exp(log_w - log_w.max())
        out = MomentEmulator(self.degree, self.alphas).fit(
            settings, trials, self.measures_, features, weights
        )
        out.box_ = self.box_
        out.local_ = {"widen": widen, "effective_settings": _effective(weights)}
        for kept in ("held_out_error_", "design_"):
            if hasattr(self, kept):
                setattr(out, kept, getattr(self, kept))
        return out

    def subset(self, names: Sequence[str]) -> MomentEmulator:
        """The same emulator over the moments `names` only."""
        idx = [self.moments_.index(n) for n in names]
        out = copy.copy(self)
        out.moments_ = list(names)
        out.coef_, out.intercept_ = self.coef_[:, idx], self.intercept_[idx]
        out.defined_, out.smearing_ = self.defined_[idx], self.smearing_[idx]
        out.noise_cov_ = self.noise_cov_[np.ix_(idx, idx)]
        out.within_var_, out.misfit_var_ = self.within_var_[idx], self.misfit_var_[idx]
        out.alpha_ = self.alpha_[idx]
        return out

    def person_noise_cov(self) -> np.ndarray:
        """One trial's noise covariance as a real session has it: the design's seeds are
        shared by VO and HV (common random numbers), a session's are not, so the
        covariance between the conditions' moments is dropped."""
        same = np.array(
            [[a.split(":")[0] == b.split(":")[0] for b in self.moments_] for a in self.moments_]
        )
        return np.where(same, self.noise_cov_, 0.0)

    def log_moments(self, traits: np.ndarray) -> np.ndarray:
        """Expected log-moments of people with `traits` (n, len(TRAITS)) -> (n, moments)."""
        return self.terms(traits) @ self.coef_ + self.intercept_

    def terms(self, traits: np.ndarray) -> np.ndarray:
        """The surface's polynomial terms of `traits` (n, len(TRAITS)): scikit-learn's
        `StandardScaler` (fitted on the design's `surface_traits`) then
        `PolynomialFeatures(degree)`, in plain numpy, as the estimator calls it thousands
        of times per fit and a pipeline's input checks took half of each call."""
        z = (surface_traits(np.atleast_2d(traits)) - self.centre_) / self.scale_
        return polynomial_terms(z, self.powers_)

    def means(self, traits: np.ndarray) -> np.ndarray:
        """Expected measures and features (own units) of people with `traits` ->
        (n, moments): the measures from their mean surface (`mean_moments_`), the
        features (and the measures of an emulator fitted without it) as exp(log surface)
        times Duan's smearing factor."""
        out = np.exp(self.log_moments(traits)) * self.smearing_
        names = getattr(self, "mean_moments_", [])
        if names:
            terms = self.terms(traits)[:, 1:]
            mean = np.exp(terms @ self.mean_coef_ + self.mean_intercept_) * self.mean_scale_
            for j, name in enumerate(names):
                if name in self.moments_:
                    out[:, self.moments_.index(name)] = mean[:, j]
        return out

    def jacobian(self, traits: np.ndarray, step: np.ndarray) -> np.ndarray:
        """d log-moment / d trait at one setting, by central differences of `step`."""
        cols = []
        for j, h in enumerate(step):
            up, down = traits.copy(), traits.copy()
            up[j] += h
            down[j] -= h
            cols.append((self.log_moments(up)[0] - self.log_moments(down)[0]) / (2 * h))
        return np.column_stack(cols)

    def to_dict(self) -> dict[str, object]:
        return {
            "surface": f"polynomial response surface (degree {self.degree}) of log measures "
            "and log features on standardised log traits (caution as it is), ridge penalty "
            "per moment by leave-one-out cross-validation",
            "mean_surface": "the measures' means on their own scale: a log-link "
            "(quasi-Poisson) regression of each measure on the same terms, penalty "
            f"{MEAN_ALPHA:g}"
            if getattr(self, "mean_moments_", [])
            else "exp(log surface) times Duan's smearing factor",
            "ridge_penalty": dict(
                zip(self.moments_, np.round(self.alpha_, 4).tolist(), strict=True)
            ),
            "settings": self.n_settings_,
            "trials": self.n_trials_,
            "r2": {k: round(float(v), 4) for k, v in self.r2_.items()},
            "features": self.features_,
            "dropped_features": getattr(self, "dropped_features_", {}),
            **(
                {
                    "held_out_trait_error": dict(
                        zip(TRAITS, np.round(self.held_out_error_, 6).tolist(), strict=True)
                    ),
                    "held_out_note": "RMS error of the traits of design settings the "
                    "emulator was not fitted to, estimated from their own trials "
                    "(4 folds; see study.analysis.participant_fit.validate)",
                }
                if hasattr(self, "held_out_error_")
                else {}
            ),
            "trial_noise_sd_log": dict(
                zip(self.moments_, np.sqrt(np.diag(self.noise_cov_)).round(4).tolist(), strict=True)
            ),
        }
