"""Training the GRU stage with PyTorch ([endovascular], eqs. 3-4 and 12-13): see `gru.py`.

Only training imports this module, so that running a trained estimator never loads
PyTorch, an optional dependency (the `train` extra; without it, importing this module
raises one line saying how to install it). `gru.pt` (a state dict for `GruNet`) is
written here beside the plain `gru.npz` that inference reads, and read only for model
folders older than `gru.npz`.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np

from teleop_core._typing import Float1D, Float2D
from teleop_core.errors import TeleopInputError
from teleop_core.progress import Progress, no_progress

try:
    import torch
except ImportError as exc:  # the `train` extra is not installed
    raise TeleopInputError(
        "training the force estimator's GRU needs PyTorch, which is not installed; expected "
        "`pip install 'haptic-study[train]'` (on a CPU-only machine `pip install "
        "torch==2.13.0` first)"
    ) from exc
from teleop_core.estimation.gru import (
    N_FEATURES,
    GruConfig,
    GruModel,
    GruWeights,
    Standardisation,
    TrainingHistory,
    block_split,
    make_windows,
)


class GruNet(torch.nn.Module):
    """GRU(inputs -> H), last hidden state -> Linear(H -> 1): sequence to one (eq. 3).
    `n_inputs` is 3 for the plain window, more with memory features (`memory.py`)."""

    def __init__(self, hidden_size: int, dropout: float = 0.0, n_inputs: int = N_FEATURES) -> None:
        super().__init__()
        self.gru = torch.nn.GRU(n_inputs, hidden_size, batch_first=True)
        # Dropout has no weights, so the state dict (and the numba kernel) is unchanged.
        self.dropout = torch.nn.Dropout(dropout)
        self.head = torch.nn.Linear(hidden_size, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _, h = self.gru(x)
        return self.head(self.dropout(h[-1])).squeeze(-1)


def weights_from_net(net: GruNet) -> GruWeights:
    return GruWeights.from_state_dict(net.state_dict())


def state_dict_of(weights: GruWeights) -> dict[str, torch.Tensor]:
    """The weights as a `GruNet` state dict."""
    return {
        "gru.weight_ih_l0": torch.tensor(weights.w_ih),
        "gru.weight_hh_l0": torch.tensor(weights.w_hh),
        "gru.bias_ih_l0": torch.tensor(weights.b_ih),
        "gru.bias_hh_l0": torch.tensor(weights.b_hh),
        "head.weight": torch.tensor(weights.w_out[None, :]),
        "head.bias": torch.tensor([weights.b_out]),
    }


def save_torch_weights(weights: GruWeights, path: Path) -> None:
    """Save the weights as a PyTorch state dict (loadable into `GruNet`)."""
    torch.save(state_dict_of(weights), path)


def load_torch_weights(path: Path) -> GruWeights:
    return GruWeights.from_state_dict(torch.load(path, weights_only=True))


def _rmse_of(net: GruNet, x: torch.Tensor, y: torch.Tensor, target_std: float) -> float:
    with torch.inference_mode():
        se = 0.0
        for lo in range(0, len(x), 4096):
            se += float(((net(x[lo : lo + 4096]) - y[lo : lo + 4096]) ** 2).sum())
    return math.sqrt(se / max(len(x), 1)) * target_std


def train_gru(
    features: Float2D,
    target: Float1D,
    config: GruConfig,
    *,
    seed: int = 0,
    target_kind: str = "residual",
    split: tuple[np.ndarray, np.ndarray] | None = None,
    progress: Progress = no_progress,
) -> tuple[GruModel, TrainingHistory, np.ndarray, np.ndarray]:
    """Train the compensator on per-sample `features` (n, config.n_inputs): [I_q,
    theta_d, theta_dd] and the memory features of `config.memory` (`GruModel.inputs`
    builds them), and `target` (n,), N.

    The target of window i is the value at its last sample. `split` gives the training
    and validation window indices (default: `block_split` with `seed`). Returns the
    model at the best validation epoch, the history (RMSE in N per epoch), and the
    indices of the training and validation windows.
    """
    if features.ndim != 2 or features.shape[1] != config.n_inputs:
        raise TeleopInputError(
            f"training inputs of shape {features.shape}; expected (n, {config.n_inputs}) "
            f"for memory features {config.memory.to_dict()['kind']}"
        )
    torch.manual_seed(seed)
    generator = torch.Generator().manual_seed(seed)
    T = config.window
    n_windows = len(features) - T + 1
    train_idx, val_idx = split or block_split(n_windows, T, config, seed)
    # Standardise with statistics of the training samples only.
    train_samples = np.unique((train_idx[:, None] + np.arange(T)).ravel())
    std = Standardisation.fit(features[train_samples], target[train_idx + T - 1])
    windows = make_windows(std.features(features), T)
    y = (target[T - 1 :] - std.target_mean) / std.target_std
    x_train = torch.tensor(windows[train_idx], dtype=torch.float32)
    y_train = torch.tensor(y[train_idx], dtype=torch.float32)
    x_val = torch.tensor(windows[val_idx], dtype=torch.float32)
    y_val = torch.tensor(y[val_idx], dtype=torch.float32)

    net = GruNet(config.hidden_size, config.dropout, config.n_inputs)
    # Fused Adam(W) and one thread: each step is a few small kernels, where thread
    # hand-offs cost more than they save (3.6 against 5.4 ms a step on two cores here)
    # and the fused update halves the optimiser's share. AdamW with weight_decay 0 is Adam.
    optimiser = torch.optim.AdamW(
        net.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay, fused=True
    )
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        history, best_state = _fit(
            net, optimiser, x_train, y_train, x_val, y_val, std, config, generator, progress
        )
    finally:
        torch.set_num_threads(threads)
    net.load_state_dict(best_state)
    model = GruModel(weights_from_net(net), std, T, target_kind, config.memory)
    return model, history, train_idx, val_idx


def _fit(
    net: GruNet,
    optimiser: torch.optim.Optimizer,
    x_train: torch.Tensor,
    y_train: torch.Tensor,
    x_val: torch.Tensor,
    y_val: torch.Tensor,
    std: Standardisation,
    config: GruConfig,
    generator: torch.Generator,
    progress: Progress,
) -> tuple[TrainingHistory, dict[str, torch.Tensor]]:
    """The epoch loop; returns the history and the best validation state."""
    history = TrainingHistory()
    best_state = copy.deepcopy(net.state_dict())
    best = math.inf
    for epoch in range(1, config.max_epochs + 1):
        net.train()
        order = torch.randperm(len(x_train), generator=generator)
        se = 0.0
        for lo in range(0, len(order), config.batch_size):
            batch = order[lo : lo + config.batch_size]
            optimiser.zero_grad(set_to_none=True)
            x = x_train[batch]
            if config.input_noise > 0:
                x = x + config.input_noise * torch.randn(x.shape, generator=generator)
            # L = 1/N sum (f_GRU(window) - r_t)^2   (eq. 12)
            loss = torch.nn.functional.mse_loss(net(x), y_train[batch])
            loss.backward()
            optimiser.step()
            se += loss.item() * len(batch)
        net.eval()
        train_rmse = math.sqrt(se / len(x_train)) * std.target_std
        val_rmse = _rmse_of(net, x_val, y_val, std.target_std)
        history.train_rmse.append(train_rmse)
        history.val_rmse.append(val_rmse)
        if val_rmse < best:
            best, history.best_epoch = val_rmse, epoch
            best_state = copy.deepcopy(net.state_dict())
        progress(f"train {train_rmse:.4f} N, validation {val_rmse:.4f} N", epoch, config.max_epochs)
        if config.patience is not None and epoch - history.best_epoch >= config.patience:
            break
    return history, best_state
