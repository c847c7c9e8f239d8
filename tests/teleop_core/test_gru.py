"""The GRU residual compensator: kernel vs PyTorch, the split, and what training buys."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from teleop_core.estimation.estimator import train_estimator
from teleop_core.estimation.gru import (
    GruConfig,
    _batch_forward,
    _exp_into,
    _window_forward,
    _window_forward_libm,
    block_split,
)
from teleop_core.estimation.gru_torch import GruNet, weights_from_net
from teleop_core.estimation.physics import PhysicsParams
from teleop_core.estimation.recording import FollowerRecording


@pytest.mark.parametrize("n_inputs", [3, 11])  # the plain window; with memory features
def test_inference_kernel_matches_torch_gru(n_inputs: int) -> None:
    torch.manual_seed(3)
    net = GruNet(hidden_size=12, n_inputs=n_inputs).double()
    x = torch.randn(50, 20, n_inputs, dtype=torch.float64)
    with torch.no_grad():
        expected = net(x).numpy()
    w = weights_from_net(net)
    got = _batch_forward(np.ascontiguousarray(x.numpy()), *w.kernel_weights())
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


def test_vector_exp_matches_libm_to_two_ulp() -> None:
    v = np.concatenate([np.linspace(-700.0, 700.0, 20001), [0.0, -0.0, 1e-300, -1e-300]])
    out, bits = np.empty_like(v), np.empty(len(v), dtype=np.int64)
    _exp_into(v.copy(), out, bits)
    np.testing.assert_allclose(out, np.exp(v), rtol=4.5e-16, atol=0)
    # beyond +-700 the argument is clamped (the gates are saturated long before)
    far = np.array([-1000.0, 1000.0])
    _exp_into(far.copy(), out[:2], bits[:2])
    np.testing.assert_array_equal(out[:2], np.exp([-700.0, 700.0]))


@pytest.mark.parametrize(
    ("n_inputs", "hidden", "scale"), [(3, 32, 1.0), (11, 12, 1.0), (3, 9, 30.0)]
)
def test_vectorised_window_within_1e_12_of_the_libm_form(
    n_inputs: int, hidden: int, scale: float
) -> None:
    # The loop ran _window_forward_libm before; the vectorised form may differ from it
    # by rounding only. scale 30 drives the gates into saturation (|pre-activation| ~ 100).
    torch.manual_seed(hidden)
    w = weights_from_net(GruNet(hidden_size=hidden, n_inputs=n_inputs).double())
    rng = np.random.default_rng(hidden)
    worst = 0.0
    for _ in range(200):
        x = rng.normal(size=(20, n_inputs)) * scale
        fast = _window_forward(x, *w.kernel_weights())
        ref = _window_forward_libm(x, w.w_ih, w.w_hh, w.b_ih, w.b_hh, w.w_out, w.b_out)
        worst = max(worst, abs(fast - ref))
    assert worst <= 1e-12


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_block_split_keeps_validation_windows_apart_from_training(seed: int) -> None:
    config = GruConfig(window=20, blocks=10)
    n_windows = 5000
    train, val = block_split(n_windows, 20, config, seed)
    train_samples = set((train[:, None] + np.arange(20)).ravel().tolist())
    val_samples = set((val[:, None] + np.arange(20)).ravel().tolist())
    assert not train_samples & val_samples
    assert len(val) / (len(train) + len(val)) == pytest.approx(0.2, abs=0.02)
    # Blocks, not scattered samples: validation is at most two contiguous runs of windows.
    assert np.count_nonzero(np.diff(val) > 1) <= 1
    again = block_split(n_windows, 20, config, seed)
    assert np.array_equal(again[1], val)


def test_gru_cuts_the_error_of_a_nonlinearity_eq_1_lacks() -> None:
    """Stribeck-like friction at low speed: eq. 1 cannot fit it, the GRU residual can."""
    rng = np.random.default_rng(7)
    n = 5000
    t = np.arange(n) * 0.01
    omega = 4 * np.sin(2 * np.pi * 0.09 * t) + 2 * np.sin(2 * np.pi * 0.37 * t + 1)
    alpha = np.gradient(omega, t)
    iq = 0.25 + 0.15 * np.sin(2 * np.pi * 0.05 * t) + rng.normal(0, 0.01, n)
    truth = PhysicsParams().force(iq, omega, alpha)
    stribeck = 0.4 * np.exp(-((omega / 0.8) ** 2)) * np.tanh(omega / 0.1)
    rec = FollowerRecording.from_arrays(
        t, iq, np.cumsum(omega) * 0.01, omega, truth - stribeck, alpha=alpha
    )
    config = GruConfig(window=5, hidden_size=16, learning_rate=3e-3, max_epochs=25)
    _, summary = train_estimator(rec, config, seed=0)
    v = summary.validation_rmse_n
    assert v["hybrid"] < 0.5 * v["physics"], v
    assert summary.best_epoch >= 2  # it learned, not a lucky initialisation
