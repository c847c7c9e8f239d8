"""The linear mixed model with one random intercept per participant, fitted by REML to
the optimum lme4 reaches with tight tolerances.

Written here rather than through statsmodels' `MixedLM`: its REML optimum stopped short
of lme4's (standard errors off by up to 1.5e-5 relative), and it warned "MLE may be on the
boundary" whenever the intercept variance was below 0.01 in the measure's units, where
lme4's `isSingular()` was FALSE. With a single random intercept the REML criterion
profiles to one parameter, the variance ratio lambda = sigma_b^2 / sigma^2, and every
term of it and of its derivative is a sum over participants (the covariance of one
participant's trials is sigma^2 (I + lambda J), inverted in closed form), so the optimum
is a root of the exact derivative, found to machine precision by Brent's method.

The REML criterion (Bates et al. 2015, lme4's `REMLcrit` up to a constant), with
V0 = I + lambda Z Z', A = X' V0^-1 X, r = y - X beta_hat and N - p residual df:

    d(lambda) = log|V0| + log|A| + (N - p) log(r' V0^-1 r)

beta_hat = A^-1 X' V0^-1 y, sigma^2 = r' V0^-1 r / (N - p), cov(beta_hat) = sigma^2 A^-1.
The fit is singular (lme4's `isSingular`, tolerance 1e-4) when theta = sqrt(lambda)
is below 1e-4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SINGULAR_TOL = 1e-4
"""lme4's `isSingular(tol = 1e-4)`: a random-effect SD ratio theta below it is a boundary fit."""


@dataclass(frozen=True)
class Fit:
    beta: np.ndarray
    se: np.ndarray
    theta: float
    """sigma_b / sigma (lme4's `getME(fit, "theta")`)."""
    sigma: float
    reml_crit: float
    """-2 REML log-likelihood (lme4's `REMLcrit`)."""

    @property
    def singular(self) -> bool:
        return self.theta < SINGULAR_TOL


def _parts(lam: float, X: np.ndarray, y: np.ndarray, idx: np.ndarray, n_i: np.ndarray):
    """The pieces of the criterion and its derivative at lambda (sums over participants)."""
    c = lam / (1 + n_i * lam)  # V0_i^-1 = I - c_i J
    sx = np.zeros((len(n_i), X.shape[1]))
    np.add.at(sx, idx, X)  # 1' X_i
    sy = np.bincount(idx, weights=y, minlength=len(n_i))  # 1' y_i
    A = X.T @ X - (sx * c[:, None]).T @ sx
    b = X.T @ y - sx.T @ (c * sy)
    beta = np.linalg.solve(A, b)
    r = y - X @ beta
    sr = np.bincount(idx, weights=r, minlength=len(n_i))
    q = r @ r - c @ sr**2  # r' V0^-1 r
    return A, beta, q, sx, sr


def _criterion(lam: float, X, y, idx, n_i) -> float:
    A, _, q, _, _ = _parts(lam, X, y, idx, n_i)
    n, p = X.shape
    return float(np.log1p(n_i * lam).sum() + np.linalg.slogdet(A)[1] + (n - p) * np.log(q))


def _gradient(lam: float, X, y, idx, n_i) -> float:
    """d criterion / d lambda: tr(V0^-1 ZZ') - tr(A^-1 X'V0^-1 ZZ' V0^-1 X)
    - (N - p) r'V0^-1 ZZ' V0^-1 r / r'V0^-1 r (beta_hat's own derivative drops out)."""
    A, _, q, sx, sr = _parts(lam, X, y, idx, n_i)
    n, p = X.shape
    w = 1 / (1 + n_i * lam)  # V0_i^-1 1 = w_i 1
    u = sx * w[:, None]  # Z' V0^-1 X
    trace = np.trace(np.linalg.solve(A, u.T @ u))
    return float((n_i * w).sum() - trace - (n - p) * ((w * sr) ** 2).sum() / q)


def fit_random_intercept(X: np.ndarray, y: np.ndarray, groups: np.ndarray) -> Fit:
    """REML fit of y = X beta + u[group] + e, u ~ N(0, sigma_b^2), e ~ N(0, sigma^2)."""
    n, p = X.shape
    if n <= p:
        raise ValueError(f"{n} trials for {p} fixed effects: no residual degrees of freedom")
    _, idx = np.unique(groups, return_inverse=True)
    n_i = np.bincount(idx).astype(float)
    args = (X, y, idx, n_i)
    if _parts(0.0, *args)[2] <= 0:
        raise ValueError("the fixed effects fit every trial exactly: no residual variance")
    if _gradient(0.0, *args) >= 0:
        lam = 0.0  # the criterion rises from the boundary: the optimum is on it
    else:
        hi = 1.0
        while _gradient(hi, *args) < 0:
            hi *= 4
            if hi > 1e12:
                raise ValueError("the random-intercept variance does not converge")
        from scipy.optimize import brentq

        lam = brentq(lambda x: _gradient(x, *args), 0.0, hi, xtol=1e-300, rtol=1e-15, maxiter=500)
    A, beta, q, _, _ = _parts(lam, *args)
    sigma2 = q / (n - p)
    se = np.sqrt(np.diag(np.linalg.inv(A)) * sigma2)
    crit = _criterion(lam, *args) + (n - p) * (1 + np.log(2 * np.pi / (n - p)))
    return Fit(
        beta=beta,
        se=se,
        theta=float(np.sqrt(lam)),
        sigma=float(np.sqrt(sigma2)),
        reml_crit=float(crit),
    )
