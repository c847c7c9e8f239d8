"""A base model plus a chain of effects as one least-squares model, and its fitted form.

This owns the arithmetic the loop repeats: building the design matrix of a chain (each
effect with its searched value fixed), solving for the coefficients on the training
rows, searching one effect's nonlinear parameter, and the confidence intervals of the
final model. `CalibratedModel` is the fitted result in a form that can be written to
JSON and rebuilt (the estimator's `--calibration` reads it back).

Confidence intervals come from the least-squares Jacobian: at the optimum the model is
linearised in every parameter (the coefficients' columns, plus a finite-difference
column per searched parameter) and that Gauss-Newton design is refitted with
statsmodels' OLS under a Newey-West (HAC) covariance, since residuals of neighbouring
samples are correlated; physical parameters get theirs by the delta method. The
nonlinear search uses `scipy.optimize.minimize_scalar` and, for the period of a
position-periodic disturbance, `scipy.signal.lombscargle` on the residual against angle.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import signal, stats
from scipy.linalg import cho_factor, cho_solve, qr
from scipy.optimize import minimize_scalar
from statsmodels.regression.linear_model import OLS

from teleop_core._typing import Bool1D, Float1D, Float2D, Int1D, Rows
from teleop_core.calibration.effects import Effect, Signals
from teleop_core.calibration.models import BaseModel, CalibrationData
from teleop_core.errors import TeleopInputError

Chain = list[tuple[Effect, float]]
"""Effects in the order added, each with its searched value (nan when it has none)."""
Z_95 = float(stats.norm.ppf(0.975))
BIN_RAD = 1e-3
"""Angle bin of the gridded periodogram, rad (a 300 rad^-1 wave loses < 2 % to it)."""
K_MIN, K_MAX = 1.0, 300.0
"""Wavenumbers searched, rad^-1: once a turn up to 300 times a turn."""


def design(model: BaseModel, s: Signals, chain: Chain) -> tuple[Float2D, list[int]]:
    """The design matrix of base + chain over all samples, and each block's column count."""
    for effect, value in chain:
        s = effect.transform(s, value)
    blocks = [model.columns(s)] + [effect.columns(s, value) for effect, value in chain]
    return np.column_stack(blocks), [b.shape[1] for b in blocks]


def solve(X: Float2D, y: Float1D) -> Float1D:
    """Least-squares coefficients, with columns scaled to comparable size first.

    Through the normal equations (Cholesky), which is 20x faster than the SVD of
    `numpy.linalg.lstsq` on tall designs and accurate enough once the columns are
    scaled; a rank-deficient design falls back to the SVD.
    """
    scale = np.maximum(np.abs(X).max(axis=0), 1e-12)
    Xs = X / scale
    coef = _solve_normal(Xs.T @ Xs, Xs.T @ y)
    if coef is None:
        coef, *_ = np.linalg.lstsq(Xs, y, rcond=None)
    return coef / scale


def _solve_normal(gram: Float2D, rhs: Float1D) -> Float1D | None:
    """(X'X) b = X'y by Cholesky for scaled columns; None where the Gram matrix is
    singular or too ill-conditioned (cond > 1e12) for the normal equations."""
    try:
        c, low = cho_factor(gram)
        coef = cho_solve((c, low), rhs)
    except np.linalg.LinAlgError:
        return None
    if np.linalg.cond(gram) > 1e12:
        return None
    return np.asarray(coef)


def train_sse(model: BaseModel, data: CalibrationData, train: Rows, chain: Chain) -> float:
    """Training SSE of base + `chain` fitted on the `train` rows (the reference path:
    the whole design built and solved; `SearchCost` is its fast form for a search)."""
    X, _ = design(model, data.signals, chain)
    coef = solve(X[train], data.y[train])
    e = data.y[train] - X[train] @ coef
    return float(e @ e)


def best_training_fit(designs: Iterable[Float2D], y: Float1D, train: Rows) -> tuple[float, Float1D]:
    """Of `designs`, the one whose least-squares fit on the `train` rows leaves the
    smallest training SSE (the first of equals): that SSE and its fitted values on
    every row (a grid search over a value that enters the design itself)."""
    best: tuple[float, Float1D] | None = None
    for X in designs:
        fit = X @ solve(X[train], y[train])
        e = y[train] - fit[train]
        sse = float(e @ e)
        if best is None or sse < best[0]:
            best = (sse, fit)
    if best is None:
        raise ValueError("best_training_fit: no design given")
    return best


class SearchCost:
    """`train_sse` of base + `chain` + (`effect`, value) as a function of the value,
    with the part that does not depend on it made once.

    The signals after the chain's transforms, the scaled training columns of base +
    chain and their Gram matrix are computed here; each call makes only the
    candidate's columns, the Gram blocks that involve them, and the residual. The
    arithmetic is `solve`'s (the same column scaling, Cholesky and conditioning rule),
    blocked, so the SSE agrees with `train_sse` to rounding. An effect that transforms
    the signals (`delay`) changes every column and goes through `train_sse`, as does a
    value whose design is too ill-conditioned for the normal equations.
    """

    def __init__(
        self, model: BaseModel, data: CalibrationData, train: Rows, chain: Chain, effect: Effect
    ) -> None:
        self.model, self.data, self.train, self.chain, self.effect = (
            model,
            data,
            train,
            chain,
            effect,
        )
        self.fast = type(effect).transform is Effect.transform
        if not self.fast:
            return
        s = data.signals
        for e, v in chain:
            s = e.transform(s, v)
        self.signals = s
        X = np.column_stack([model.columns(s)] + [e.columns(s, v) for e, v in chain])[train]
        scale = np.maximum(np.abs(X).max(axis=0), 1e-12)
        self.scale = scale
        self.As = np.ascontiguousarray(X / scale)
        self.y = np.ascontiguousarray(data.y[train])
        self.gram = self.As.T @ self.As
        self.rhs = self.As.T @ self.y

    def __call__(self, value: float) -> float:
        """Training SSE with the candidate's searched parameter at `value`."""
        if not self.fast:
            return train_sse(self.model, self.data, self.train, [*self.chain, (self.effect, value)])
        C = self.effect.columns(self.signals, value)[self.train]
        c_scale = np.maximum(np.abs(C).max(axis=0), 1e-12)
        Cs = C / c_scale
        cross = self.As.T @ Cs
        gram = np.block([[self.gram, cross], [cross.T, Cs.T @ Cs]])
        coef = _solve_normal(gram, np.concatenate([self.rhs, Cs.T @ self.y]))
        if coef is None:
            return train_sse(self.model, self.data, self.train, [*self.chain, (self.effect, value)])
        k = self.As.shape[1]
        e = self.y - self.As @ coef[:k] - Cs @ coef[k:]
        return float(e @ e)


def search(
    model: BaseModel, data: CalibrationData, train: Rows, chain: Chain, effect: Effect
) -> float:
    """The searched value of `effect` (added to `chain`) that fits the training rows best."""
    if effect.searched is None:
        return float("nan")

    cost = SearchCost(model, data, train, chain, effect)

    if effect.family == "position_periodic":
        grid, brackets = _periodogram_peaks(model, data, train, chain)
    else:
        grid = effect.grid(data.signals)
        brackets = [_bracket(grid, i) for i in range(len(grid))]
    costs = np.array([cost(v) for v in grid])
    order = np.argsort(costs)[: 3 if effect.family == "position_periodic" else 1]
    best_value, best_cost = float(grid[order[0]]), float(costs[order[0]])
    for i in order if effect.refine else ():
        lo, hi = brackets[i]
        if effect.family == "position_periodic":
            # the phase drifts by 2 pi over the angle covered when the period is off by
            # one frequency resolution: refine to a hundredth of the bracket
            res = minimize_scalar(
                cost, bounds=(lo, hi), method="bounded", options={"xatol": (hi - lo) / 200}
            )
            value = float(res.x)
        elif effect.log_search:
            res = minimize_scalar(
                lambda u: cost(float(np.exp(u))),
                bounds=(np.log(lo), np.log(hi)),
                method="bounded",
                options={"xatol": 1e-3, "maxiter": 25},
            )
            value = float(np.exp(res.x))
        else:
            res = minimize_scalar(
                cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3, "maxiter": 25}
            )
            value = float(res.x)
        if res.fun < best_cost:
            best_value, best_cost = value, float(res.fun)
    return best_value


def _bracket(grid: Float1D, i: int) -> tuple[float, float]:
    """The grid's neighbours of point i (the interval a scalar refinement searches)."""
    g = np.sort(grid)
    j = int(np.searchsorted(g, grid[i]))
    return float(g[max(j - 1, 0)]), float(g[min(j + 1, len(g) - 1)])


def _periodogram_peaks(
    model: BaseModel, data: CalibrationData, train: Rows, chain: Chain, count: int = 6
) -> tuple[Float1D, list[tuple[float, float]]]:
    """Periods (rad) at the largest peaks of the training residual's periodogram in
    angle, each with the bracket (one frequency resolution either side) to refine in.

    The Schuster periodogram |sum_j e_j exp(-i k theta_j)|^2, gridded: residuals are
    summed into angle bins of `BIN_RAD` and transformed with numpy's FFT. scipy's
    `lombscargle` computes the same sums directly, O(samples x frequencies), which
    took seconds on a 30 s recording; the gridded form takes milliseconds.
    """
    X, _ = design(model, data.signals, chain)
    e = data.y[train] - X[train] @ solve(X[train], data.y[train])
    angle = data.signals["angle"][train]
    bins = ((angle - angle.min()) / BIN_RAD).astype(np.int64)
    sums = np.bincount(bins, weights=e - e.mean())
    n_fft = 1 << int(np.ceil(np.log2(max(4 * len(sums), 64))))
    power = np.abs(np.fft.rfft(sums, n=n_fft)) ** 2
    k = 2 * np.pi * np.fft.rfftfreq(n_fft, d=BIN_RAD)  # wavenumber, rad^-1
    band = (k >= K_MIN) & (k <= K_MAX)
    peaks, _ = signal.find_peaks(np.where(band, power, 0.0))
    if len(peaks) == 0:  # pragma: no cover - a residual with no structure in angle at all
        peaks = np.flatnonzero(band)[:1]
    top = peaks[np.argsort(power[peaks])[::-1][:count]]
    dk = 2 * np.pi / max(float(np.ptp(angle)), 2 * np.pi)
    periods = 2 * np.pi / k[top]
    brackets = [(2 * np.pi / (kk + dk), 2 * np.pi / max(kk - dk, K_MIN / 2)) for kk in k[top]]
    return periods, brackets


@dataclass
class CalibratedModel:
    """A base model with fitted coefficients and effects; JSON round trip via to_dict."""

    model: BaseModel
    chain: Chain
    coef: Float1D
    settings: dict[str, Any] = field(default_factory=dict)

    def predict(self, data: CalibrationData) -> Float1D:
        """Model force (N) over every sample of `data`."""
        X, _ = design(self.model, data.signals, self.chain)
        return X @ self.coef

    def to_dict(self) -> dict[str, Any]:
        return {
            "base": self.model.name,
            "base_settings": self.settings,
            "effects": [
                {"family": e.family, "searched_value": v, **e.saved_settings} for e, v in self.chain
            ],
            "coefficients": [float(c) for c in self.coef],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CalibratedModel:
        # here, not at the top: importing teleop_core.calibration.registry imports this module
        from teleop_core.calibration.registry import BASE_MODELS

        try:
            base = BASE_MODELS[d["base"]]
            settings = dict(d.get("base_settings", {}))
            if settings:
                base = type(base)(**settings)
            chain = [(_saved_effect(base, e), float(e["searched_value"])) for e in d["effects"]]
            coef = np.asarray(d["coefficients"], float)
        except (KeyError, TypeError, ValueError) as exc:
            raise TeleopInputError(f"calibrated model is damaged: {exc!r}") from None
        return cls(base, chain, coef, settings)


def _saved_effect(base: BaseModel, saved: dict[str, Any]) -> Effect:
    """The effect of a saved model's entry: the family as `base` uses it, or the form
    it had when saved where the entry lacks that form's settings (a follower's
    direction asymmetry saved before it had its reverse gain column)."""
    effect = base.effect(saved["family"])
    if any(saved.get(k) != v for k, v in effect.saved_settings.items()):
        return effect.saved_before or effect
    return effect


def determined_columns(X: Float2D) -> tuple[Int1D, Bool1D]:
    """Of the columns of `X` (scaled to comparable size): a set spanning the same space
    with none a combination of the others (QR with column pivoting, numpy's rank
    tolerance), and the mask of the columns whose coefficient the least-squares fit
    does not determine (those in a combination that gives 0: a zero column, or a term
    that sums from others)."""
    _, singular, vt = np.linalg.svd(X, full_matrices=False)
    tol = singular.max(initial=0.0) * max(X.shape) * np.finfo(float).eps
    rank = int(np.sum(singular > tol))
    if rank == X.shape[1]:
        return np.arange(rank), np.zeros(rank, bool)
    _, _, pivots = qr(X, mode="economic", pivoting=True)
    return np.sort(pivots[:rank]), np.linalg.norm(vt[rank:], axis=0) > 1e-8


def params_text(params: dict[str, float], ci: dict[str, list[float] | None], digits: int) -> str:
    """`name = value [low, high]` per parameter (`confidence`'s values and intervals),
    `[no interval]` where the fit does not determine it; `digits` significant."""
    return ", ".join(
        f"{k} = {v:.4g} "
        + ("[no interval]" if c is None else f"[{c[0]:.{digits}g}, {c[1]:.{digits}g}]")
        for (k, v), c in zip(params.items(), ci.values(), strict=True)
    )


def confidence(
    fitted: CalibratedModel, data: CalibrationData, train: Rows, hac_lags: int = 10
) -> tuple[dict[str, float], dict[str, list[float] | None], list[dict[str, Any]]]:
    """Physical parameters of the base and of each effect with 95 % intervals.

    Returns (base params, base CIs, [{"params", "ci"} per effect in chain order]). A
    parameter the linearised fit does not determine has no interval (None): a searched
    value the design does not change with at the finite-difference step (a step's time
    between two samples), or a term that is a sum of others. The covariance comes from
    the columns that do span the design (`determined_columns`); they leave the same
    residual, so the other intervals are as with the whole design.
    """
    model, chain, coef = fitted.model, fitted.chain, fitted.coef
    X, sizes = design(model, data.signals, chain)
    searched = [i for i, (e, _) in enumerate(chain) if e.searched is not None]
    jac = [X[train]]
    for i in searched:
        e, v = chain[i]
        h = 1e-4 * abs(v) if e.log_search else 1e-4
        up = [*chain[:i], (e, v + h), *chain[i + 1 :]]
        down = [*chain[:i], (e, v - h), *chain[i + 1 :]]
        d = (design(model, data.signals, up)[0] - design(model, data.signals, down)[0]) @ coef
        jac.append((d[train] / (2 * h))[:, None])
    J = np.column_stack(jac)
    scale = np.maximum(np.abs(J).max(axis=0), 1e-12)
    basis, free = determined_columns(J / scale)
    ols = OLS(data.y[train], J[:, basis] / scale[basis]).fit(
        cov_type="HAC", cov_kwds={"maxlags": hac_lags}
    )
    cov = np.zeros((J.shape[1], J.shape[1]))
    cov[np.ix_(basis, basis)] = np.asarray(ols.cov_params()) / np.outer(scale[basis], scale[basis])
    theta = np.concatenate([coef, [chain[i][1] for i in searched]])

    def physical(th: Float1D) -> list[dict[str, float]]:
        c = th[: len(coef)]
        values = dict(zip(searched, th[len(coef) :], strict=True))
        out = [model.physical(c[: sizes[0]])]
        start = sizes[0]
        for i, ((e, v), k) in enumerate(zip(chain, sizes[1:], strict=True)):
            params = e.physical(c[start : start + k], values.get(i, v), model.out, model.unit)
            out.append(model.rename(e.family, params))
            start += k
        return out

    base_values = physical(theta)
    flat = np.array([v for d in base_values for v in d.values()])
    G = np.empty((len(flat), len(theta)))
    for j in range(len(theta)):
        step = 1e-6 * max(abs(theta[j]), 1e-12)
        th = theta.copy()
        th[j] += step
        G[:, j] = (np.array([v for d in physical(th) for v in d.values()]) - flat) / step
    se = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", G, cov, G), 0.0))
    # a physical parameter that moves with an undetermined one has no interval
    undetermined = np.any(G[:, free] != 0.0, axis=1)
    results, pos = [], 0
    for group in base_values:
        ci: dict[str, list[float] | None] = {
            k: None
            if undetermined[pos + j]
            else [float(val - Z_95 * se[pos + j]), float(val + Z_95 * se[pos + j])]
            for j, (k, val) in enumerate(group.items())
        }
        results.append(({k: float(v) for k, v in group.items()}, ci))
        pos += len(group)
    base_params, base_ci = results[0]
    return base_params, base_ci, [{"params": p, "ci": c} for p, c in results[1:]]
