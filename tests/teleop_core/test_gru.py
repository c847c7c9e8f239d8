"""The GRU residual compensator: kernel vs PyTorch, the split, and what training buys."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from teleop_core.estimation.gru import (
    GruConfig,
    GruWeights,
    _batch_forward,
    _tanh32_into,
    block_split,
)
from teleop_core.estimation.gru_torch import GruNet, state_dict_of, weights_from_net
from teleop_core.estimation.training import train_estimator
from teleop_core.follower.physics import PhysicsParams
from teleop_core.follower.recording import FollowerRecording

SHIPPED = Path(__file__).resolve().parents[2] / "study" / "models" / "follower_estimator"


GRU_F32_TOLERANCE = 2e-6
"""How far (in the network's standardised output) the float32 kernel may be from torch's
own float32 GRU on the same windows: both round in float32 (sums of 32 products over 20
steps; torch's float32 output is itself some 5e-7 from a float64 evaluation here)."""


def _torch_and_kernel(net: GruNet, x: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    with torch.no_grad():
        expected = net(x).double().numpy()
    w = weights_from_net(net)
    got = _batch_forward(np.ascontiguousarray(x.numpy(), dtype=np.float64), *w.kernel_weights())
    return got, expected


@pytest.mark.parametrize(
    ("n_inputs", "hidden", "scale"), [(3, 32, 1.0), (11, 12, 1.0), (3, 9, 30.0)]
)
def test_inference_kernel_matches_torch_float32_gru(
    n_inputs: int, hidden: int, scale: float
) -> None:
    # The plain window, with memory features, and (scale 30) gates driven into saturation
    # (|pre-activation| ~ 100): the network in float32, as PyTorch trains it.
    torch.manual_seed(hidden)
    net = GruNet(hidden_size=hidden, n_inputs=n_inputs)
    got, expected = _torch_and_kernel(net, torch.randn(300, 20, n_inputs) * scale)
    assert np.max(np.abs(got - expected)) <= GRU_F32_TOLERANCE
    assert np.ptp(expected) > 0.05  # the outputs vary: not a test of a constant


def test_inference_kernel_matches_torch_on_the_shipped_network() -> None:
    # The network the loop runs by default, on standardised windows
    w = GruWeights.load_npz(SHIPPED / "gru.npz")
    net = GruNet(hidden_size=w.w_hh.shape[1], n_inputs=w.n_inputs)
    net.load_state_dict({k: v.float() for k, v in state_dict_of(w).items()})
    torch.manual_seed(0)
    got, expected = _torch_and_kernel(net, torch.randn(1000, 20, w.n_inputs) * 1.5)
    assert np.max(np.abs(got - expected)) <= GRU_F32_TOLERANCE
    assert np.ptp(expected) > 1.0


def test_float32_tanh_within_3e_7_of_tanh() -> None:
    v = np.concatenate([np.linspace(-20.0, 20.0, 400_001), [0.0, 1e-30, -1e-30, 1e30, -1e30]])
    v32 = v.astype(np.float32)
    out = np.empty_like(v32)
    _tanh32_into(v32, out)
    assert np.max(np.abs(out.astype(np.float64) - np.tanh(v32.astype(np.float64)))) <= 3e-7
    mirrored = np.empty_like(v32)
    _tanh32_into(-v32, mirrored)
    np.testing.assert_array_equal(mirrored, -out)  # odd, as tanh


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
