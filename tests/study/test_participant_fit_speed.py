"""The participant fit's faster paths against the forms they replace.

- `polynomial_terms` (two gathered columns of [1, z, z ** 2] per term) against the
  product of every column's power it replaced, bit for bit, and against scikit-learn's
  `PolynomialFeatures` on the standardised traits;
- the emulator's statistics with BLAS on one thread (`one_blas_thread`, as the fit runs
  them) against two threads: the same numbers;
- the LCCA trial's `approaches` (vectorised) against the loop it replaced, and its
  frame made from the loop's sample array against the frame of the loop's frame;
- `holm_flags` against statsmodels' `multipletests(method="holm")`, which it replaced;
- `worker_pool`: two `simulate_settings` calls on one pool started once, their trials
  those of the same settings simulated in this process.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd
import pytest
from sklearn.preprocessing import PolynomialFeatures, StandardScaler
from threadpoolctl import threadpool_limits

from study.analysis.participant_fit import simulate
from study.analysis.participant_fit.checks import holm_flags
from study.analysis.participant_fit.emulator import (
    MomentEmulator,
    design_box,
    design_settings,
    polynomial_terms,
    surface_traits,
)
from study.protocol.traits import TRAITS
from study.tasks.lcca.features import OSTIUM_BAND_M, approaches
from teleop_core.blas import one_blas_thread
from tests.study.test_participant_fit_validate import MEASURES, synthetic_trials


def _old_terms(z: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """The form `polynomial_terms` replaced."""
    return np.prod(z[:, None, :] ** powers[None], axis=2)


@pytest.mark.parametrize("degree", [1, 2, 3])
@pytest.mark.parametrize("rows", [1, 2, 9, 4000])
def test_polynomial_terms_equal_the_product_of_powers_bit_for_bit(degree: int, rows: int) -> None:
    rng = np.random.default_rng(rows + 10 * degree)
    # values of every scale the standardised traits take, and beyond
    z = rng.normal(size=(rows, 7)) * rng.choice([1e-3, 1.0, 3.0, 40.0], size=(rows, 7))
    powers = PolynomialFeatures(degree).fit(z).powers_
    new = polynomial_terms(z, powers)
    assert new.shape == (rows, len(powers))
    assert np.array_equal(new, _old_terms(z, powers))


def test_the_emulators_terms_are_scikit_learns_pipeline() -> None:
    x = design_settings(60, 4, design_box())
    emulator = MomentEmulator().fit(x, synthetic_trials(np.zeros((60, 2)), 1, _rng()), MEASURES)
    scaled = StandardScaler().fit(surface_traits(x)).transform(surface_traits(x[:7]))
    reference = PolynomialFeatures(2).fit_transform(scaled)
    np.testing.assert_allclose(emulator.terms(x[:7]), reference, rtol=1e-13, atol=1e-13)


def _rng() -> np.random.Generator:
    return np.random.default_rng(5)


def _emulator_numbers() -> list[np.ndarray]:
    x = design_settings(120, 2, design_box())
    speed, caution = x[:, TRAITS.index("preferred_speed_m_s")], x[:, TRAITS.index("caution")]
    logs = np.column_stack([np.log(0.25 / speed), np.log(0.4 + 0.5 * caution)])
    emulator = MomentEmulator().fit(x, synthetic_trials(logs, 2, _rng()), MEASURES)
    return [emulator.coef_, emulator.alpha_, emulator.noise_cov_, emulator.means(x[:20])]


def test_the_emulators_statistics_on_one_blas_thread_equal_two_threads() -> None:
    with threadpool_limits(limits=2, user_api="blas"):
        two = _emulator_numbers()
    one = one_blas_thread(_emulator_numbers)()
    for a, b in zip(one, two, strict=True):
        assert np.array_equal(a, b)


def test_one_worker_pool_serves_several_simulations_with_the_same_trials(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    opened = []
    new_pool = simulate._new_pool

    def counted(task: str, jobs: int) -> ProcessPoolExecutor:
        opened.append((task, jobs))
        return new_pool(task, jobs)

    monkeypatch.setattr(simulate, "_new_pool", counted)
    x = design_settings(3, 1, design_box())
    people = [{"group": "design", **dict(zip(TRAITS, row, strict=True))} for row in x]
    # short trials: the pool and the trials' identity matter here, not their ends
    with simulate.worker_pool("lcca", 2):
        design = simulate.simulate_settings("lcca", people, 1, jobs=2, max_s=4.0)
        check = simulate.simulate_settings("lcca", people[:2], 1, 2, 4.0, salt="check")
    assert opened == [("lcca", 2)]
    alone = simulate.simulate_settings("lcca", people, 1, jobs=1, max_s=4.0)
    alone_check = simulate.simulate_settings("lcca", people[:2], 1, 1, 4.0, salt="check")
    assert design.equals(alone)
    assert check.equals(alone_check)
    # outside the pool a call opens its own again
    simulate.simulate_settings("lcca", people[:2], 1, jobs=2, max_s=1.0)
    assert opened == [("lcca", 2), ("lcca", 2)]


@pytest.mark.parametrize("seed", range(6))
def test_holm_flags_are_statsmodels_multipletests(seed: int) -> None:
    from statsmodels.stats.multitest import multipletests

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 30))
    # small p-values near Holm's thresholds, ties, ones and (seed 5) a NaN
    p = np.where(rng.random(n) < 0.5, rng.random(n) * 0.05, rng.random(n))
    p[rng.integers(0, n, 3)] = p[0]
    p[-1] = 0.05 / n if seed % 2 else 1.0
    if seed == 5:
        p[n // 2] = np.nan
    rows = [{"p": float(v)} for v in p]
    holm_flags(rows, 0.05)
    reject, p_holm, _, _ = multipletests(p, 0.05, method="holm")
    assert [r["flagged"] for r in rows] == reject.tolist()
    np.testing.assert_array_equal([r["p_holm"] for r in rows], p_holm)


def _approaches_loop(x: np.ndarray, ostium_m: float) -> int:
    """The loop `approaches` replaced: armed behind the ostium, counted when near it."""
    near = x >= ostium_m - OSTIUM_BAND_M
    behind = x < ostium_m - 1.5 * OSTIUM_BAND_M
    count, armed = 0, True
    for k in np.flatnonzero(near | behind):
        if near[k] and armed:
            count, armed = count + 1, False
        elif behind[k]:
            armed = True
    return count


@pytest.mark.parametrize("seed", range(4))
def test_approaches_count_as_the_loop_did(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for n in (0, 1, 2, 50, 3000):
        # a wandering insertion about the ostium, and one that jumps across it
        walk = 0.2 + np.cumsum(rng.normal(0.0, 0.004, n))
        jumps = rng.uniform(0.17, 0.23, n)
        for x in (walk, jumps):
            assert approaches(x, 0.2) == _approaches_loop(x, 0.2)
    # by hand: near, behind, the band between (neither), near, near, behind, near
    x = 0.2 + np.array([0.0, -0.02, -0.01, -0.005, 0.001, -0.02, 0.0])
    assert approaches(x, 0.2) == 3


def test_the_trials_frame_from_the_sample_array_is_the_frame_of_the_loops_frame() -> None:
    from study.protocol.traits import ParticipantTraits
    from study.tasks.lcca.simulated_participant import SimulatedParticipant
    from study.tasks.lcca.trial import TRIAL_COLUMNS, lcca_loop, trial_frame
    from teleop_core.phantom.lcca import LccaPhantom

    phantom = LccaPhantom()
    x = design_settings(2, 0, design_box())
    traits = ParticipantTraits(group="design", **dict(zip(TRAITS, x[0], strict=True)))
    result = lcca_loop("HV", 3, None, None, phantom).run(
        6.0, SimulatedParticipant(traits, phantom, give_up_s=6.0)
    )
    assert len(result.samples) > 100
    # the reference: the loop's own frame of every column, in TRIAL.csv's order
    old = result.to_frame()[list(TRIAL_COLUMNS)]
    pd.testing.assert_frame_equal(trial_frame(result.samples), old, check_exact=True)
