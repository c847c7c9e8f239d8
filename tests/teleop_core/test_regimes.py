"""Regime labels and the validation split that must hold every regime."""

from __future__ import annotations

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.estimation.gru import GruConfig, block_split
from teleop_core.estimation.ranges import InputRange
from teleop_core.estimation.regimes import (
    LABELS,
    RegimeRules,
    label_samples,
    regime_rmse,
    representative_split,
)

RULES = RegimeRules(load_low_n=0.5, load_high_n=1.0)


def test_labels_follow_the_rules_on_a_hand_built_profile() -> None:
    # 100 Hz: 1 s at rest, 1 s slow forward (0.5 rad/s), 1 s fast forward (3 rad/s), then
    # a jump to 3 rad/s backward (a reversal around t = 3 s), 1 s fast backward.
    omega = np.r_[np.zeros(100), np.full(100, 0.5), np.full(100, 3.0), np.full(100, -3.0)]
    f_ref = np.r_[np.full(100, 0.2), np.full(100, 0.7), np.full(200, 1.5)]
    m = label_samples(omega, f_ref, 100.0, RULES)
    # reversal window 0.25 s = 25 samples, centred: samples 288..312 see both signs
    reversal = np.zeros(400, bool)
    reversal[288:312] = True
    np.testing.assert_array_equal(m["speed:reversal"], reversal)
    assert m["speed:rest"][:100].all()
    assert not m["speed:rest"][100:].any()
    assert m["speed:slow"][100:200].all()
    assert m["speed:slow"].sum() == 100
    assert m["speed:fast"].sum() == 200 - 24
    assert m["direction:backward"].sum() == 100
    assert m["direction:none"].sum() == 100
    assert (m["load:low"].sum(), m["load:mid"].sum(), m["load:high"].sum()) == (100, 100, 200)
    # each dimension labels every sample exactly once
    for dim, names in (("speed", 4), ("direction", 3), ("load", 3)):
        stacked = np.array([m[k] for k in LABELS if k.startswith(dim)])
        assert len(stacked) == names
        assert (stacked.sum(axis=0) == 1).all()


def _rare_regime_masks(n: int) -> dict[str, np.ndarray]:
    """Forward fast motion throughout but for two short backward stretches (blocks 3
    and 16 of 20), the only backward motion and the only reversals."""
    omega = np.full(n, 3.0)
    for block in (3, 16):
        lo = block * n // 20 + n // 80
        omega[lo : lo + n // 100] = -3.0
    f_ref = np.linspace(0.0, 2.0, n) % 1.3
    return label_samples(omega, f_ref, 100.0, RegimeRules.for_loads(f_ref))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_split_puts_a_rare_regime_in_both_parts(seed: int) -> None:
    n, T = 20_000, 20
    masks = _rare_regime_masks(n)
    train, val, report = representative_split(masks, n - T + 1, T, 20, 0.2, seed)
    assert report["missing"] == []
    backward = masks["direction:backward"]
    assert backward[train + T - 1].any()
    assert backward[val + T - 1].any()
    train_samples = set((train[:, None] + np.arange(T)).ravel().tolist())
    val_samples = set((val[:, None] + np.arange(T)).ravel().tolist())
    assert not train_samples & val_samples
    assert len(val) / (len(train) + len(val)) == pytest.approx(0.2, abs=0.02)
    assert set(report["share"]) == set(LABELS)


def test_a_random_choice_of_blocks_often_misses_the_rare_regime() -> None:
    """The old rule (seeded random blocks): what the regime-covering split replaces."""
    n, T = 20_000, 20
    backward = _rare_regime_masks(n)["direction:backward"]
    misses = 0
    for seed in range(20):
        _, val = block_split(n - T + 1, T, GruConfig(window=T, blocks=20), seed)
        misses += not backward[val + T - 1].any()
    # 4 of 20 blocks validate; P(neither of the two blocks) = C(18,4)/C(20,4) = 0.63
    assert misses >= 6


def test_regime_rmse_matches_a_hand_computation() -> None:
    masks = {k: np.zeros(4, bool) for k in LABELS}
    masks["speed:rest"][:] = [True, True, False, False]
    masks["speed:fast"][:] = [False, False, True, True]
    truth = np.array([0.0, 0.0, 1.0, 1.0])
    est = np.array([0.3, -0.4, 1.0, 2.0])
    table = regime_rmse(masks, truth, physics=est)
    assert set(table) == {"speed:rest", "speed:fast"}
    assert table["speed:rest"]["physics"] == pytest.approx(np.sqrt((0.09 + 0.16) / 2))
    assert table["speed:fast"] == {"samples": 2, "physics": pytest.approx(np.sqrt(0.5))}


def test_rules_and_ranges_refuse_nonsense() -> None:
    with pytest.raises(TeleopInputError, match="rest < slow"):
        RegimeRules(rest_speed_rad_s=2.0)
    with pytest.raises(TeleopInputError, match="low <= high"):
        RegimeRules(load_low_n=1.0, load_high_n=0.5)
    with pytest.raises(TeleopInputError, match="expected 3"):
        InputRange((0.0,), (1.0,))


def test_input_range_flags_each_input_that_leaves_it() -> None:
    train = np.array([[0.0, -1.0, -10.0], [0.5, 2.0, 10.0]])
    rng = InputRange.fit(train)
    rows = np.array(
        [[0.25, 0.0, 0.0], [0.5, 2.0, 10.0], [0.6, 0.0, 0.0], [0.1, -1.5, 0.0], [0.1, 0, 11.0]]
    )
    np.testing.assert_array_equal(rng.contains(rows), [True, True, False, False, False])
    assert rng.outside_by_feature(rows) == {"iq": 0.2, "omega": 0.2, "alpha": 0.2}
    assert InputRange.from_dict(rng.to_dict()) == rng
