"""The linear mixed model with one random intercept per participant: the REML fit
(statsmodels' `MixedLM`, polished to lme4's optimum) and the small-sample inference on
its fixed effects and contrasts (Satterthwaite's df as lmerTest computes them, or
Kenward-Roger's as pbkrtest does).

The fit is statsmodels' `MixedLM(y, X, groups).fit(reml=True)`. Its optimiser stops on
a gradient tolerance that leaves the variance ratio a little short of the optimum
(its standard errors then differ from lme4's in the fifth digit), so the fit is polished from
statsmodels' start: with one random intercept the profiled REML log-likelihood has one
parameter, theta = sigma_b / sigma (statsmodels' packed square-root parameter), and the
root of statsmodels' own analytic score (`MixedLM.score`, fixed effects and scale
profiled out) is found by `scipy.optimize.brentq` to machine precision. The fit is on
the boundary (lme4's `isSingular`) when theta is below `SINGULAR_TOL`; the score then
does not change sign on (0, start] and theta = 0.

No Python library computes Satterthwaite's or Kenward-Roger's degrees of freedom for a
mixed model (statsmodels' `MixedLMResults` gives Wald z tests only), so both are written
here, from the definitions the R packages implement:

- Satterthwaite (lmerTest, Kuznetsova et al. 2017): with varpar = (theta, sigma), the
  asymptotic covariance of varpar is A = 2 H^-1, H the Hessian of the REML deviance
  in varpar (lmerTest's `devfun_vp`); for a contrast L, with g the gradient of
  L Var(beta) L' in varpar, df = 2 (L Var(beta) L')^2 / (g' A g). lmerTest takes both
  derivatives numerically (numDeriv's Richardson extrapolation); here every derivative
  is a closed form over the participant sums below except the second in theta, which
  is `scipy.differentiate.derivative` of the closed-form first one (a numerical
  Hessian of the whole deviance loses digits to the deviance's size in sigma).
- Kenward-Roger (Kenward and Roger 1997; pbkrtest's `vcovAdj` and `Lb_ddf`, which
  lmerTest's `ddf = "Kenward-Roger"` calls): the adjusted covariance PhiA of beta from
  the variance components (sigma_b^2, sigma^2) with G_1 = Z Z' and G_2 = I, and the
  one-dimensional df of `Lb_ddf`.

The REML deviance (lmerTest's `devfun_vp`, lme4's `REMLcrit` at its optimum), with
V0 = I + theta^2 Z Z', A = X' V0^-1 X, r = y - X beta_hat(theta), N trials, p fixed
effects:

    d(theta, sigma) = log|V0| + log|A| + r' V0^-1 r / sigma^2 + (N - p) log(2 pi sigma^2)

Every term is a sum over participants, since V0_i^-1 = I - c_i J with
c_i = theta^2 / (1 + n_i theta^2).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

SINGULAR_TOL = 1e-4
"""lme4's `isSingular(tol = 1e-4)`: a random-effect SD ratio theta below it is a boundary fit."""
BOUNDARY_TOL = 1e-10
"""A log-likelihood gain below this (absolute) does not move theta off the boundary."""
DDF_METHODS = ("Satterthwaite", "Kenward-Roger")
"""The small-sample df of the fixed effects' t tests (lmerTest's `ddf`)."""


@dataclass(frozen=True)
class Design:
    """y = X beta + u[participant] + e, with the participant sums the criterion needs."""

    X: np.ndarray
    """Fixed-effects design, one row per trial; shape (N, p)."""
    y: np.ndarray
    """Response, one per trial; shape (N,)."""
    idx: np.ndarray
    """Participant index of each trial, 0..m-1; shape (N,)."""
    n_i: np.ndarray
    """Trials per participant; shape (m,)."""

    @classmethod
    def of(cls, X: np.ndarray, y: np.ndarray, groups: np.ndarray) -> Design:
        _, idx = np.unique(np.asarray(groups), return_inverse=True)
        return cls(np.asarray(X, float), np.asarray(y, float), idx, np.bincount(idx).astype(float))

    def sums(self, theta: float) -> tuple[np.ndarray, np.ndarray, float]:
        """A = X' V0^-1 X, beta_hat and r' V0^-1 r at theta."""
        c = theta**2 / (1 + self.n_i * theta**2)  # V0_i^-1 = I - c_i J
        sx = np.zeros((len(self.n_i), self.X.shape[1]))
        np.add.at(sx, self.idx, self.X)  # 1' X_i
        sy = np.bincount(self.idx, weights=self.y, minlength=len(self.n_i))
        A = self.X.T @ self.X - (sx * c[:, None]).T @ sx
        beta = np.linalg.solve(A, self.X.T @ self.y - sx.T @ (c * sy))
        r = self.y - self.X @ beta
        sr = np.bincount(self.idx, weights=r, minlength=len(self.n_i))
        return A, beta, float(r @ r - c @ sr**2)

    def deviance(self, theta: float, sigma: float) -> float:
        """The REML deviance d(theta, sigma) of the module docstring (lmerTest's `devfun_vp`)."""
        A, _, q = self.sums(theta)
        n, p = self.X.shape
        log_v0 = float(np.log1p(self.n_i * theta**2).sum())
        return (
            log_v0
            + float(np.linalg.slogdet(A)[1])
            + q / sigma**2
            + (n - p) * float(np.log(2 * np.pi * sigma**2))
        )

    def vcov(self, theta: float, sigma: float) -> np.ndarray:
        """Var(beta_hat) = sigma^2 (X' V0^-1 X)^-1 (lmerTest's `get_covbeta`)."""
        return sigma**2 * np.linalg.inv(self.sums(theta)[0])


@dataclass(frozen=True)
class Fit:
    """A REML fit and the inference on its fixed effects (`fit_random_intercept`)."""

    design: Design
    beta: np.ndarray
    """Fixed effects; shape (p,)."""
    vcov: np.ndarray
    """Their covariance sigma^2 (X' V0^-1 X)^-1 (lme4's `vcov`); shape (p, p)."""
    theta: float
    """sigma_b / sigma (lme4's `getME(fit, "theta")`)."""
    sigma: float
    """Residual SD (lme4's `sigma`)."""
    reml_crit: float
    """-2 REML log-likelihood (lme4's `REMLcrit`)."""

    @property
    def se(self) -> np.ndarray:
        return np.sqrt(np.diag(self.vcov))

    @property
    def singular(self) -> bool:
        return self.theta < SINGULAR_TOL

    @cached_property
    def varpar_parts(self) -> VarparParts:
        """`varpar_covariance` of this fit, computed once for all its contrasts."""
        return varpar_covariance(self)

    def contrast(self, L: np.ndarray, ddf: str = "Satterthwaite") -> Contrast:
        """The t test of L beta = 0 with `ddf`'s degrees of freedom.

        Parameters
        ----------
        L : numpy.ndarray
            The contrast's weights on the fixed effects; shape (p,).
        ddf : str, optional
            "Satterthwaite" (lmerTest's default) or "Kenward-Roger".

        Returns
        -------
        Contrast
            Estimate, SE (Kenward-Roger: from the adjusted covariance), df, t and p.
        """
        L = np.asarray(L, float)
        if ddf == "Satterthwaite":
            var, df = L @ self.vcov @ L, satterthwaite_df(self, L)
        elif ddf == "Kenward-Roger":
            var, df = kenward_roger(self, L)
        else:
            raise ValueError(f"ddf {ddf!r}; expected one of {', '.join(DDF_METHODS)}")
        return Contrast.of(float(L @ self.beta), float(np.sqrt(var)), df)


@dataclass(frozen=True)
class Contrast:
    estimate: float
    se: float
    df: float
    t: float
    p: float
    """Two-sided, from the t distribution with `df` degrees of freedom."""
    ci_low: float
    ci_high: float
    """The 95 % confidence interval, estimate -/+ t_.975(df) SE."""

    @classmethod
    def of(cls, estimate: float, se: float, df: float) -> Contrast:
        # lazy: scipy costs 0.7 s at start-up
        from scipy import stats

        t = estimate / se if se > 0 else float("nan")
        half = float(stats.t.ppf(0.975, df)) * se
        p = float(2 * stats.t.sf(abs(t), df)) if np.isfinite(t) else float("nan")
        return cls(estimate, se, float(df), float(t), p, estimate - half, estimate + half)


def _polished_theta(
    model, start: float, width: float = 0.5, rtol: float = 4 * np.finfo(float).eps
) -> float:
    """The root of statsmodels' profiled REML score in theta, bracketed from `start`
    (start x (1 -/+ width), widened until the score changes sign; 0 when the
    log-likelihood falls from the boundary), to `rtol` relative."""
    # lazy: scipy.optimize costs 0.4 s at start-up
    from scipy.optimize import brentq

    def score(theta: float) -> float:
        return float(model.score(np.array([theta]), profile_fe=True)[0])

    lo = max(start, 1e-3) * (1 - width)
    while score(lo) <= 0:  # the log-likelihood falls already here: the optimum is lower
        lo /= 4
        if lo < SINGULAR_TOL * 1e-4:
            return 0.0
    hi = max(start, 1e-3) * (1 + width)
    while score(hi) > 0:
        hi *= 4
        if hi > 1e8:
            raise ValueError("the random-intercept variance does not converge")
    return float(brentq(score, lo, hi, xtol=1e-300, rtol=rtol, maxiter=500))


def _start(model) -> float:
    """statsmodels' REML estimate of theta (BFGS, Powell if BFGS fails: L-BFGS's first
    steps can reach a variance at which X' V^-1 X is singular)."""
    for method in ("bfgs", "powell"):
        try:
            fit = model.fit(reml=True, method=[method])
        except (np.linalg.LinAlgError, ValueError):
            continue
        return float(np.sqrt(max(float(np.asarray(fit.cov_re)[0, 0]), 0.0) / fit.scale))
    return 1.0


def _theta(model, design: Design) -> float:
    """The REML theta: statsmodels' score's root (or the boundary where statsmodels'
    score falls from it), started from `_bracket`, or from statsmodels' own fit where
    `_bracket` has no start."""
    start = _bracket(design)
    if start is None:
        return _polished_theta(model, _start(model))
    model = _unfitted(model)
    if start == 0.0:
        # the closed form's deviance rises from the boundary: statsmodels' likelihood
        # confirms it where it falls at lme4's singular tolerance and is no higher there
        # than at 0 (most boundary fits); otherwise a rough root from statsmodels' smallest
        # start decides, and only an interior one is polished
        edge = np.array([SINGULAR_TOL])
        if float(model.score(edge, profile_fe=True)[0]) <= 0 and _boundary_fits_as_well(
            model, SINGULAR_TOL * (1 - 1e-9)
        ):
            return 0.0
        rough = _polished_theta(model, 0.0, rtol=1e-6)
        if rough == 0.0 or _boundary_fits_as_well(model, rough):
            return 0.0
        return _polished_theta(model, rough, width=1e-5, rtol=1e-13)
    return _polished_theta(model, start, width=1e-6, rtol=1e-13)


def _boundary_fits_as_well(model, theta: float) -> bool:
    """A root this close to 0 that fits no better than theta = 0 is the boundary's."""
    return 0 < theta < SINGULAR_TOL and model.loglike(np.array([0.0]), profile_fe=True) >= (
        model.loglike(np.array([theta]), profile_fe=True) - BOUNDARY_TOL
    )


def _unfitted(model):
    """`model` set up for its REML score as `MixedLM.fit` sets it (no penalties, every
    parameter free), without the fit."""
    model.reml, model.cov_pen, model.fe_pen, model._cov_sing, model._freepat = (
        True, None, None, 0, None
    )  # fmt: skip
    return model


def _bracket(d: Design) -> float | None:
    """Where the profiled REML deviance's closed-form derivative in theta (the one
    Satterthwaite's df use, `_theta_derivatives`) vanishes: only the start of the
    polish on statsmodels' score, which decides the optimum, so that the model is not
    fitted twice (statsmodels' BFGS, then the polish). None when it has no root in
    (1e-6, 1e6) (a boundary fit or a flat criterion: statsmodels' own fit starts)."""
    # lazy: scipy.optimize costs 0.4 s at start-up
    from scipy.optimize import brentq

    n, p = d.X.shape

    def slope(theta: float) -> float:
        dlogdet, dq, _, _ = _theta_derivatives(d, theta)
        return dlogdet + (n - p) * dq / d.sums(theta)[2]

    try:
        lo, hi = 1e-6, 1e6
        if slope(lo) >= 0:
            return 0.0  # the deviance rises from the boundary
        if not slope(hi) > 0:
            return None
        return float(brentq(slope, lo, hi, rtol=1e-12))
    except (np.linalg.LinAlgError, ValueError, ZeroDivisionError):
        return None


_FITS: dict[tuple[object, ...], Fit] = {}
"""The fits made so far in this process, by their data (`fit_random_intercept`)."""
_FITS_KEPT = 64


def fit_random_intercept(X: np.ndarray, y: np.ndarray, groups: np.ndarray) -> Fit:
    """REML fit of y = X beta + u[group] + e, u ~ N(0, sigma_b^2), e ~ N(0, sigma^2).

    Parameters
    ----------
    X : numpy.ndarray
        Fixed-effects design of full column rank; shape (N, p).
    y : numpy.ndarray
        Response; shape (N,).
    groups : numpy.ndarray
        Participant of each trial; shape (N,).

    Returns
    -------
    Fit
        Fixed effects and their covariance at lme4's REML optimum.

    Raises
    ------
    ValueError
        No residual degrees of freedom, no residual variance, or a variance that does not
        converge.
    """
    X, y = np.ascontiguousarray(X, float), np.ascontiguousarray(y, float)
    key = (X.shape, X.tobytes(), y.tobytes(), tuple(map(str, groups)))
    if key not in _FITS:  # the same model of the same data is fitted once per process
        if len(_FITS) >= _FITS_KEPT:
            _FITS.pop(next(iter(_FITS)))
        _FITS[key] = _fit_random_intercept(X, y, groups)
    return _FITS[key]


def _fit_random_intercept(X: np.ndarray, y: np.ndarray, groups: np.ndarray) -> Fit:
    # the one module, not statsmodels.api (which imports every model and data set)
    from statsmodels.regression.mixed_linear_model import MixedLM

    # lazy: statsmodels.tools.sm_exceptions costs 0.5 s at start-up
    from statsmodels.tools.sm_exceptions import ConvergenceWarning

    design = Design.of(X, y, groups)
    n, p = design.X.shape
    if n <= p:
        raise ValueError(f"{n} trials for {p} fixed effects: no residual degrees of freedom")
    if design.sums(0.0)[2] <= 1e-24 * float(design.y @ design.y):
        raise ValueError("the fixed effects fit every trial exactly: no residual variance")
    model = MixedLM(design.y, design.X, groups=design.idx)
    with warnings.catch_warnings():  # boundary and convergence: the polish below decides
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        warnings.simplefilter("ignore", UserWarning)
        theta = _theta(model, design)
        if _boundary_fits_as_well(model, theta):
            theta = 0.0
    A, beta, q = design.sums(theta)
    sigma = float(np.sqrt(q / (n - p)))
    return Fit(
        design=design,
        beta=beta,
        vcov=sigma**2 * np.linalg.inv(A),
        theta=theta,
        sigma=sigma,
        reml_crit=design.deviance(theta, sigma),
    )


def satterthwaite_df(fit: Fit, L: np.ndarray) -> float:
    """Satterthwaite's df of L beta, as lmerTest (module docstring).

    Parameters
    ----------
    fit : Fit
        The REML fit.
    L : numpy.ndarray
        The contrast; shape (p,).

    Returns
    -------
    float
        2 (L V L')^2 / (g' A g).
    """
    sigma = fit.sigma
    parts = fit.varpar_parts
    Ai, dA = parts.A_inv, parts.dA
    # Var(beta) = sigma^2 A^-1: d/d theta = -sigma^2 A^-1 A' A^-1, d/d sigma = 2 sigma A^-1
    g = np.array([-(sigma**2) * L @ Ai @ dA @ Ai @ L, 2 * sigma * L @ Ai @ L])
    return float(2 * (L @ fit.vcov @ L) ** 2 / (g @ parts.cov @ g))


class VarparParts(NamedTuple):
    """What Satterthwaite's df take from a fit, whatever the contrast."""

    cov: np.ndarray
    """2 H^-1, the asymptotic covariance of varpar = (theta, sigma); H the REML
    deviance's Hessian in varpar (module docstring); shape (2, 2)."""
    A_inv: np.ndarray
    """(X' V0^-1 X)^-1 at the fit's theta; shape (p, p)."""
    dA: np.ndarray
    """d (X' V0^-1 X) / d theta; shape (p, p)."""


def varpar_covariance(fit: Fit) -> VarparParts:
    """The fit's `VarparParts`.

    The derivatives in sigma are closed forms; those in theta are closed forms for the
    first derivative (beta_hat's own derivative drops out of q' at the GLS optimum) and
    `scipy.differentiate.derivative` of it for the second. They depend on the fit alone,
    not on the contrast: `Fit.varpar_parts` keeps them for every contrast of one fit.
    """
    # lazy: scipy.differentiate costs 0.1 s at start-up
    from scipy.differentiate import derivative

    d, sigma = fit.design, fit.sigma
    n, p = d.X.shape
    _, _, q = d.sums(fit.theta)
    _, dq, Ai, dA = _theta_derivatives(d, fit.theta)

    def first(theta: float) -> float:
        dlogdet, dq_theta, _, _ = _theta_derivatives(d, theta)
        return dlogdet + dq_theta / sigma**2

    h_tt = derivative(np.vectorize(first), fit.theta).df
    # d^2 dev / d theta d sigma = -2 q' / sigma^3
    # d^2 dev / d sigma^2 = 6 q / sigma^4 - 2 (N - p) / sigma^2
    H = np.array(
        [
            [float(h_tt), -2 * dq / sigma**3],
            [-2 * dq / sigma**3, 6 * q / sigma**4 - 2 * (n - p) / sigma**2],
        ]
    )
    return VarparParts(2 * np.linalg.inv(H), Ai, dA)


def _theta_derivatives(d: Design, theta: float) -> tuple[float, float, np.ndarray, np.ndarray]:
    """(d/d theta of log|V0| + log|A|, d/d theta of r' V0^-1 r, A^-1, dA/d theta) at theta."""
    A, beta, _ = d.sums(theta)
    # c_i = theta^2 / (1 + n_i theta^2), dc_i / d theta = 2 theta / (1 + n_i theta^2)^2
    dc = 2 * theta / (1 + d.n_i * theta**2) ** 2
    sx = np.zeros((len(d.n_i), d.X.shape[1]))
    np.add.at(sx, d.idx, d.X)
    sr = np.bincount(d.idx, weights=d.y - d.X @ beta, minlength=len(d.n_i))
    dA = -(sx * dc[:, None]).T @ sx  # A = X'X - sum c_i sx_i sx_i'
    Ai = np.linalg.inv(A)
    dlogdet = float((2 * theta * d.n_i / (1 + d.n_i * theta**2)).sum() + np.trace(Ai @ dA))
    return dlogdet, float(-(dc * sr**2).sum()), Ai, dA


def _kr_parts(fit: Fit) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """pbkrtest's `vcovAdj`: the adjusted covariance PhiA, the P_i and W (dense: a
    study's trials are a few hundred)."""
    d = fit.design
    n = len(d.y)
    Z = np.zeros((n, len(d.n_i)))
    Z[np.arange(n), d.idx] = 1.0
    G = [Z @ Z.T, np.eye(n)]
    # Sigma = sigma_b^2 Z Z' + sigma^2 I
    Sigma = (fit.theta * fit.sigma) ** 2 * G[0] + fit.sigma**2 * G[1]
    Si = np.linalg.inv(Sigma)
    Phi = fit.vcov
    T = Si @ d.X
    H = [g @ Si for g in G]
    HX = [h @ d.X for h in H]  # pbkrtest's OO
    P = [-(o.T @ T) for o in HX]
    Q = {(i, j): HX[i].T @ Si @ HX[j] for i in range(2) for j in range(i, 2)}
    IE2 = np.empty((2, 2))
    for i in range(2):
        for j in range(i, 2):
            k = np.sum(H[i].T * H[j])
            IE2[i, j] = IE2[j, i] = (
                k - 2 * np.sum(Phi * Q[i, j]) + np.sum((Phi @ P[i]) * (P[j] @ Phi))
            )
    W = 2 * (
        np.linalg.inv(IE2) if min(abs(np.linalg.eigvalsh(IE2))) > 1e-10 else np.linalg.pinv(IE2)
    )
    U = W[0, 1] * (Q[0, 1] - P[0] @ Phi @ P[1])
    U = U + U.T
    for i in range(2):
        U = U + W[i, i] * (Q[i, i] - P[i] @ Phi @ P[i])
    return Phi + 2 * Phi @ U @ Phi, P, W


def kenward_roger(fit: Fit, L: np.ndarray) -> tuple[float, float]:
    """Kenward-Roger's adjusted variance and df of L beta (pbkrtest's `vcovAdj`, `Lb_ddf`).

    Parameters
    ----------
    fit : Fit
        The REML fit.
    L : numpy.ndarray
        The contrast; shape (p,).

    Returns
    -------
    tuple of (float, float)
        L PhiA L' and the df.
    """
    PhiA, P, W = _kr_parts(fit)
    V0 = fit.vcov
    Lm = L[None, :]
    Theta = Lm.T @ np.linalg.solve(Lm @ V0 @ Lm.T, Lm)
    A1 = A2 = 0.0
    for i in range(2):
        for j in range(i, 2):
            e = 1 if i == j else 2
            ui = Theta @ V0 @ P[i] @ V0
            uj = Theta @ V0 @ P[j] @ V0
            A1 += e * W[i, j] * np.trace(ui) * np.trace(uj)
            A2 += e * W[i, j] * np.sum(ui * uj.T)
    q = 1
    B = (A1 + 6 * A2) / (2 * q)
    g = ((q + 1) * A1 - (q + 4) * A2) / ((q + 2) * A2)
    c1 = g / (3 * q + 2 * (1 - g))
    c2 = (q - g) / (3 * q + 2 * (1 - g))
    c3 = (q + 2 - g) / (3 * q + 2 * (1 - g))
    v0 = 1 + c1 * B
    v0 = 0.0 if abs(v0) < 1e-10 else v0
    v1, v2 = 1 - c2 * B, 1 - c3 * B
    ratio = 1.0 if abs(1 - A2 / q) < 1e-14 and abs(v1) < 1e-14 else (1 - A2 / q) / v1
    rho = ratio**2 * v0 / v2 / q
    return float(L @ PhiA @ L), float(4 + (q + 2) / (q * rho - 1))
