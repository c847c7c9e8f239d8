"""The calibration loop's fast paths against the reference forms they replace.

- `SearchCost` (a candidate's training SSE from the design of base + chain made once)
  against `train_sse` (the whole design built and solved for every value);
- the Diebold-Mariano test's closed-form Newey-West variance against statsmodels' OLS
  on a constant with `cov_type="HAC"`;
- `fit_sign_speed` (the normal equations with only the sign's column new per width)
  against the least-squares fit of the whole design per width;
- `null_share` (bin indices shifted) against `binned_share` of the shifted quantity;
- `one_blas_thread`: BLAS on one thread inside, as before outside.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from statsmodels.regression.linear_model import OLS
from threadpoolctl import threadpool_info

from teleop_core.blas import one_blas_thread
from teleop_core.calibration.effects import EFFECTS
from teleop_core.calibration.fitting import SearchCost, train_sse
from teleop_core.calibration.models import (
    SIGN_WIDTHS_RAD_S,
    CalibrationData,
    FollowerBase,
    _sse_with,
    fit_sign_speed,
)
from teleop_core.calibration.residual import diebold_mariano
from teleop_core.calibration.synthetic import follower_recording
from teleop_core.calibration.verdict import BINS, SHIFTS, binned_share, null_share

MODEL = FollowerBase(sign_speed_rad_s=0.3)
TRAIN = slice(0, 2250)


@pytest.fixture(scope="module")
def data() -> CalibrationData:
    rec, _ = follower_recording(30.0, ["stribeck", "hysteresis"], rate_hz=100.0, seed=3)
    return MODEL.data(rec)


def _values(effect, data: CalibrationData) -> np.ndarray:  # type: ignore[no-untyped-def]
    grid = effect.grid(data.signals)
    return grid[:: max(1, len(grid) // 6)]


@pytest.mark.parametrize(
    "family",
    [
        "stribeck",
        "viscous_nonlinear",
        "position_periodic",
        "delay",
        "load_friction",
        "gain_change",
        "presliding_memory",
    ],
)
@pytest.mark.parametrize(
    "chain_families", [(), ("hysteresis", "drift"), ("delay", "direction_asymmetry")]
)
def test_search_cost_is_the_training_sse_of_the_whole_design(
    data: CalibrationData, family: str, chain_families: tuple[str, ...]
) -> None:
    """Every value of the candidate's grid, after a chain with and without a transform
    (`delay` shifts the signals every later column is made from)."""
    values = {"hysteresis": 0.05, "drift": 20.0, "delay": 0.03}
    chain = [(MODEL.effect(f), values.get(f, float("nan"))) for f in chain_families]
    effect = MODEL.effect(family)
    cost = SearchCost(MODEL, data, TRAIN, chain, effect)
    candidates = _values(effect, data) if effect.searched else [float("nan")]
    for value in candidates:
        reference = train_sse(MODEL, data, TRAIN, [*chain, (effect, float(value))])
        assert cost(float(value)) == pytest.approx(reference, rel=1e-9, abs=0.0)


def test_search_cost_falls_back_on_a_rank_deficient_design(data: CalibrationData) -> None:
    """A candidate that repeats a column of the chain leaves the normal equations
    singular: the SSE is still the least-squares one (the SVD's), and equals the
    SSE of the chain alone, since the repeated column adds nothing."""
    stribeck = EFFECTS["stribeck"]
    chain = [(stribeck, 0.5)]
    cost = SearchCost(MODEL, data, TRAIN, chain, stribeck)
    alone = train_sse(MODEL, data, TRAIN, chain)
    assert cost(0.5) == pytest.approx(train_sse(MODEL, data, TRAIN, [*chain, (stribeck, 0.5)]))
    assert cost(0.5) == pytest.approx(alone, rel=1e-9)


def _reference_sign_speed(data: CalibrationData, chain: list) -> tuple[float, list[float]]:
    """`fit_sign_speed` as first written: lstsq of the whole design for every width."""
    signals = data.signals
    for effect, value in chain:
        signals = effect.transform(signals, value)
    extra = [effect.columns(signals, value) for effect, value in chain]
    target = data.y[TRAIN]
    sse = []
    for width in SIGN_WIDTHS_RAD_S:
        base = FollowerBase(sign_speed_rad_s=float(width)).columns(signals)
        X = np.column_stack([base, *extra])[TRAIN]
        coef, *_ = np.linalg.lstsq(X, target, rcond=None)
        sse.append(float(np.sum((target - X @ coef) ** 2)))
    near = np.flatnonzero(np.asarray(sse) <= 1.001 * min(sse))
    return float(SIGN_WIDTHS_RAD_S[near[0]]), sse


@pytest.mark.parametrize(
    "chain_families", [(), ("hysteresis", "drift"), ("delay", "direction_asymmetry")]
)
def test_sign_width_fit_is_the_whole_designs_least_squares(
    data: CalibrationData, chain_families: tuple[str, ...]
) -> None:
    values = {"hysteresis": 0.05, "drift": 20.0, "delay": 0.03}
    chain = [(MODEL.effect(f), values.get(f, float("nan"))) for f in chain_families]
    width, sse = _reference_sign_speed(data, chain)
    assert fit_sign_speed(FollowerBase(), data.signals, data.y, TRAIN, chain) == width
    # the SSE per width, with the sign's column joined last to the scaled others
    signals = data.signals
    for effect, value in chain:
        signals = effect.transform(signals, value)
    base = FollowerBase().columns(signals)
    fixed = np.column_stack(
        [np.delete(base, 3, axis=1)] + [e.columns(signals, v) for e, v in chain]
    )[TRAIN]
    fixed = fixed / np.abs(fixed).max(axis=0)
    y = data.y[TRAIN]
    for w, expected in list(zip(SIGN_WIDTHS_RAD_S, sse, strict=True))[::6]:
        sign = FollowerBase(sign_speed_rad_s=float(w)).columns(signals)[TRAIN, 3]
        got = _sse_with(fixed, fixed.T @ fixed, fixed.T @ y, sign, y)
        assert got == pytest.approx(expected, rel=1e-9)


def test_sign_width_sse_falls_back_on_a_repeated_column(data: CalibrationData) -> None:
    """The sign's column already among the others: singular normal equations, the
    SVD's SSE, which is the SSE without the repeated column."""
    y = data.y[TRAIN]
    base = MODEL.columns(data.signals)[TRAIN]
    fixed = base / np.abs(base).max(axis=0)
    alone = y - fixed @ np.linalg.lstsq(fixed, y, rcond=None)[0]
    got = _sse_with(fixed, fixed.T @ fixed, fixed.T @ y, base[:, 3], y)
    assert got == pytest.approx(float(alone @ alone), rel=1e-9)


def _statsmodels_dm(error_a: np.ndarray, error_b: np.ndarray, lags: int) -> float:
    d = np.abs(error_a) - np.abs(error_b)
    fit = OLS(d, np.ones_like(d)).fit(cov_type="HAC", cov_kwds={"maxlags": lags})
    return float(stats.norm.sf(fit.tvalues[0]))


@pytest.mark.parametrize(("n", "shift"), [(12000, 0.0), (3000, 0.004), (200, -0.01), (60, 0.02)])
def test_diebold_mariano_is_statsmodels_hac_ols(n: int, shift: float) -> None:
    """Autocorrelated errors (a 10-sample moving average of white noise), b's smaller,
    equal on average or larger; the default lag count and a given one."""
    rng = np.random.default_rng(n)
    a = np.convolve(rng.normal(0, 0.1, n + 9), np.ones(10) / 10, "valid")
    b = a * (1.0 - shift * 10) + rng.normal(0, 0.01, n)
    default_lags = int(np.ceil(4 * (n / 100) ** (2 / 9)))
    for lags in (default_lags, 3):
        expected = _statsmodels_dm(a, b, lags)
        got = diebold_mariano(a, b, None if lags == default_lags else lags)
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-15)


def _reference_null(residual: np.ndarray, x: np.ndarray) -> np.ndarray:
    """`null_share` as first written: `binned_share` of each shifted x, re-binned."""
    n = len(x)
    offsets = np.random.default_rng(0).integers(n // 10, n - n // 10, size=SHIFTS)
    return np.array([binned_share(residual, np.roll(x, int(k)), BINS)[0] for k in offsets])


@pytest.mark.parametrize("kind", ["continuous", "ties", "three values", "constant"])
def test_null_share_is_binned_share_of_the_shifted_quantity(kind: str) -> None:
    rng = np.random.default_rng(5)
    n = 5000
    residual = np.cumsum(rng.normal(size=n)) * 0.01 + rng.normal(size=n)
    x = {
        "continuous": np.sin(np.linspace(0, 40, n)) + 0.1 * rng.normal(size=n),
        "ties": np.round(rng.normal(size=n), 1),
        "three values": np.sign(np.sin(np.linspace(0, 30, n))),
        "constant": np.full(n, 2.0),
    }[kind]
    np.testing.assert_allclose(null_share(residual, x), _reference_null(residual, x), rtol=1e-12)


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_blas_thread_limits_inside_and_restores_after() -> None:
    before = _blas_threads()
    inside = one_blas_thread(_blas_threads)()
    assert inside
    assert all(n == 1 for n in inside)
    assert _blas_threads() == before
