"""The emulator: a task's per-person moments as a smooth function of the traits.

Running the physics for every candidate trait distribution is what makes
simulation-based inference slow (0.1-0.7 s per LCCA trial). Instead, a designed set of
trait settings (a Latin hypercube over the priors' range, `scipy.stats.qmc`) is
simulated once with common random numbers (`simulate.py`), and each moment, the log of
a measure in a condition, is regressed on the traits: a quadratic response surface
(scikit-learn's `PolynomialFeatures` + `Ridge` on standardised traits). What the
regression leaves is the trial-to-trial noise (plus the surface's misfit, so the noise
is not understated); its covariance across moments is kept, since one trial's time and
forces move together. The means the report compares are on the measures' own scale (a
group's mean peak force is a mean of forces, not of logs): exp(surface) times the mean
of exp(residual), Duan's smearing estimate, which needs no assumption on the noise's
distribution (peak forces have long right tails).

`fit` returns self and the fitted values end in `_`, as in scikit-learn. The moment
names are `CONDITION:measure` (`VO:completion_time_s`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy.stats import qmc
from sklearn.linear_model import Ridge
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import PolynomialFeatures, StandardScaler

from study.protocol.design import KNOWN_CONDITIONS
from study.protocol.participants import PROFILES, TRAIT_BOUNDS, TRAITS, GroupProfile

LOG_FLOOR = 1e-3
"""Smallest value taken before a log (a peak force of 0 N reads as 1 mN)."""
DESIGN_SDS = 2.5
"""The design spans every prior group mean +/- this many prior SDs (within the bounds)."""


def moment_names(measures: Sequence[str]) -> list[str]:
    return [f"{c}:{m}" for c in KNOWN_CONDITIONS for m in measures]


def log_moment(values: np.ndarray | pd.Series) -> np.ndarray:
    return np.log(np.maximum(np.asarray(values, dtype=float), LOG_FLOOR))


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


def trial_matrix(trials: pd.DataFrame, measures: Sequence[str]) -> pd.DataFrame:
    """One row per (setting, repeat): every condition's measures side by side, with the
    columns `moment_names(measures)`."""
    wide = trials.pivot_table(
        index=["setting", "repeat"], columns="condition", values=list(measures), aggfunc="first"
    )
    return pd.DataFrame({f"{c}:{m}": wide[(m, c)] for c in KNOWN_CONDITIONS for m in measures})


def _surface(degree: int, alpha: float) -> Pipeline:
    return make_pipeline(StandardScaler(), PolynomialFeatures(degree), Ridge(alpha=alpha))


class MomentEmulator:
    """Log-moments and measure means of one person as functions of the traits.

    Parameters
    ----------
    degree
        Of the polynomial response surface (2: quadratic, with interactions).
    alpha
        Ridge penalty on the standardised features (small: keeps the fit stable where
        the design is thin, without shrinking what the data show).
    """

    def __init__(self, degree: int = 2, alpha: float = 1.0) -> None:
        self.degree = degree
        self.alpha = alpha

    def fit(
        self, settings: np.ndarray, trials: pd.DataFrame, measures: Sequence[str]
    ) -> MomentEmulator:
        """`settings` (n, len(TRAITS)); `trials` from `simulate_settings` over them."""
        self.measures_ = list(measures)
        self.moments_ = moment_names(measures)
        wide = trial_matrix(trials, measures)
        x = settings[wide.index.get_level_values("setting")]
        y = log_moment(wide[self.moments_].to_numpy(float))
        self.log_surface_ = _surface(self.degree, self.alpha).fit(x, y)
        resid = y - self.log_surface_.predict(x)
        self.smearing_ = np.exp(resid).mean(axis=0)
        # noise of one trial's log-moments (and the surface's misfit), across moments
        self.noise_cov_ = np.atleast_2d(np.cov(resid, rowvar=False))
        total = y.var(axis=0)
        self.r2_ = dict(
            zip(self.moments_, 1 - resid.var(axis=0) / np.where(total > 0, total, 1), strict=True)
        )
        self.n_settings_, self.n_trials_ = len(settings), len(trials)
        self.box_ = (settings.min(axis=0), settings.max(axis=0))
        return self

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
        return self.log_surface_.predict(np.atleast_2d(traits))

    def means(self, traits: np.ndarray) -> np.ndarray:
        """Expected measures (own units) of people with `traits` -> (n, moments)."""
        return np.exp(self.log_moments(traits)) * self.smearing_

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
            "surface": f"quadratic response surface (degree {self.degree}, ridge {self.alpha:g}) "
            "of log measures on standardised traits",
            "settings": self.n_settings_,
            "trials": self.n_trials_,
            "r2": {k: round(float(v), 4) for k, v in self.r2_.items()},
            "trial_noise_sd_log": dict(
                zip(self.moments_, np.sqrt(np.diag(self.noise_cov_)).round(4).tolist(), strict=True)
            ),
        }
