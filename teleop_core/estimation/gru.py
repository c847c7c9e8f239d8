"""The GRU stage: a sequence-to-one GRU over the last T samples of [I_q, theta_d, theta_dd].

Training (PyTorch) follows seed 000, eqs. 3-4 and 12-13: the residual compensator
learns r_t = F_ref,t - F_physics,t (eq. 13) by minimising the mean squared error of
eq. 12, with Adam, lr 1e-4, batch 32, up to 100 epochs, on standardised inputs; the
checkpoint with the lowest validation RMSE is kept. The split is by contiguous time
block (windows that straddle a train/validation boundary are dropped), never by
random samples, so validation windows share no samples with training windows. The
direct variant (Table III) learns F_ref itself with the same network.

Inference does not use PyTorch: the trained weights run through a small numba kernel
in float64. One window costs ~40 us there against ~300 us for `torch.nn.GRU` on this
machine's CPU, which is what lets the estimator sit inside a 1 kHz simulation loop.
The same compiled function serves one window (causal, sample by sample) and every
window of a recording (batch), so the two agree to the last bit. A test checks the
kernel against `torch.nn.GRU`.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numba
import numpy as np
import torch
from numpy.lib.stride_tricks import sliding_window_view

from teleop_core._typing import Float1D, Float2D, Float3D
from teleop_core.errors import TeleopInputError

N_FEATURES = 3
"""[I_q, theta_d, theta_dd] per time step."""


PATIENCE = 10
WEIGHT_DECAY = 1e-3
DROPOUT = 0.0
INPUT_NOISE = 0.0
"""Regularisation defaults (issue 17), chosen by `study bench follower`'s generalisation
runs: see README."""


@dataclass(frozen=True)
class GruConfig:
    """Network and training settings (defaults: seed 000, IV-C)."""

    window: int = 20
    """T, samples per input window (Fig. 8: RMSE levels off at 20)."""
    hidden_size: int = 32
    """GRU hidden units; assumption (the paper calls the network lightweight)."""
    learning_rate: float = 1e-4
    batch_size: int = 32
    max_epochs: int = 100
    validation_fraction: float = 0.2
    blocks: int = 20
    """Contiguous time blocks the recording is cut into for the train/validation split."""
    patience: int | None = PATIENCE
    """Stop after this many epochs without a better validation RMSE (None: never)."""
    weight_decay: float = WEIGHT_DECAY
    """Decoupled weight decay of AdamW (0: the paper's plain Adam)."""
    dropout: float = DROPOUT
    """Dropout on the last hidden state during training (0: none)."""
    input_noise: float = INPUT_NOISE
    """SD of Gaussian noise added to the standardised training inputs (0: none)."""

    def __post_init__(self) -> None:
        for name in ("window", "hidden_size", "batch_size", "max_epochs", "blocks"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise TeleopInputError(f"GruConfig.{name} = {value!r}; expected an integer >= 1")
        if self.patience is not None and (not isinstance(self.patience, int) or self.patience < 1):
            raise TeleopInputError(f"GruConfig.patience = {self.patience!r}; expected >= 1")
        for name in ("weight_decay", "input_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise TeleopInputError(f"GruConfig.{name} = {value!r}; expected >= 0")
        if not 0 <= self.dropout < 1:
            raise TeleopInputError(f"GruConfig.dropout = {self.dropout!r}; expected 0 <= p < 1")
        if not 0 < self.validation_fraction < 1:
            raise TeleopInputError(
                f"validation_fraction {self.validation_fraction!r}; expected between 0 and 1"
            )
        if not (math.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise TeleopInputError(f"learning_rate {self.learning_rate!r}; expected > 0")


@dataclass(frozen=True)
class Standardisation:
    """Per-feature mean and standard deviation of the inputs, and the target's scale."""

    feature_mean: tuple[float, ...]
    feature_std: tuple[float, ...]
    target_mean: float
    target_std: float

    @classmethod
    def fit(cls, features: Float2D, target: Float1D) -> Standardisation:
        std = features.std(axis=0)
        return cls(
            tuple(features.mean(axis=0).tolist()),
            tuple(np.where(std > 0, std, 1.0).tolist()),
            float(target.mean()),
            float(target.std()) or 1.0,
        )

    def features(self, x: Float2D) -> Float2D:
        return (x - np.asarray(self.feature_mean)) / np.asarray(self.feature_std)

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


class GruNet(torch.nn.Module):
    """GRU(3 -> H), last hidden state -> Linear(H -> 1): sequence to one (eq. 3)."""

    def __init__(self, hidden_size: int, dropout: float = 0.0) -> None:
        super().__init__()
        self.gru = torch.nn.GRU(N_FEATURES, hidden_size, batch_first=True)
        # Dropout has no weights, so the state dict (and the numba kernel) is unchanged.
        self.dropout = torch.nn.Dropout(dropout)
        self.head = torch.nn.Linear(hidden_size, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _, h = self.gru(x)
        return self.head(self.dropout(h[-1])).squeeze(-1)


@dataclass(frozen=True)
class GruWeights:
    """A trained network in float64 numpy arrays for the inference kernel."""

    w_ih: Float2D  # (3H, 3), gates in torch's order r, z, n
    w_hh: Float2D  # (3H, H)
    b_ih: Float1D
    b_hh: Float1D
    w_out: Float1D  # (H,)
    b_out: float

    @classmethod
    def from_state_dict(cls, state: dict[str, torch.Tensor]) -> GruWeights:
        """From a `GruNet` state dict (any dtype), as float64 contiguous arrays."""
        sd = {k: v.detach().cpu().double().numpy() for k, v in state.items()}
        return cls(
            np.ascontiguousarray(sd["gru.weight_ih_l0"]),
            np.ascontiguousarray(sd["gru.weight_hh_l0"]),
            np.ascontiguousarray(sd["gru.bias_ih_l0"]),
            np.ascontiguousarray(sd["gru.bias_hh_l0"]),
            np.ascontiguousarray(sd["head.weight"][0]),
            float(sd["head.bias"][0]),
        )

    @classmethod
    def from_net(cls, net: GruNet) -> GruWeights:
        return cls.from_state_dict(net.state_dict())

    def to_state_dict(self) -> dict[str, torch.Tensor]:
        return {
            "gru.weight_ih_l0": torch.tensor(self.w_ih),
            "gru.weight_hh_l0": torch.tensor(self.w_hh),
            "gru.bias_ih_l0": torch.tensor(self.b_ih),
            "gru.bias_hh_l0": torch.tensor(self.b_hh),
            "head.weight": torch.tensor(self.w_out[None, :]),
            "head.bias": torch.tensor([self.b_out]),
        }


@numba.njit(cache=True, fastmath={"reassoc", "contract", "arcp", "nsz", "afn"})
def _window_forward(x, w_ih, w_hh, b_ih, b_hh, w_out, b_out):  # type: ignore[no-untyped-def]  # pragma: no cover
    # h' = (1 - z) n + z h, with r, z = sigma(W_i x + b_i + W_h h + b_h) and
    # n = tanh(W_in x + b_in + r (W_hn h + b_hn))   (torch.nn.GRU's equations)
    # Each gate is computed in its own loop over contiguous memory and reassociation is
    # allowed (not the no-NaN/no-inf assumptions), so LLVM vectorises the sums:
    # 25 us instead of 54 us per window of 20 at H = 32 on this machine.
    n_hidden = w_hh.shape[1]
    h = np.zeros(n_hidden)
    gh = np.empty(3 * n_hidden)
    gi = np.empty(3 * n_hidden)
    r = np.empty(n_hidden)
    z = np.empty(n_hidden)
    n = np.empty(n_hidden)
    for t in range(x.shape[0]):
        # gh = W_hh h + b_hh and gi = W_ih x + b_ih (from the previous h)
        for j in range(3 * n_hidden):
            acc = b_hh[j]
            for k in range(n_hidden):
                acc += w_hh[j, k] * h[k]
            gh[j] = acc
            gi[j] = b_ih[j] + w_ih[j, 0] * x[t, 0] + w_ih[j, 1] * x[t, 1] + w_ih[j, 2] * x[t, 2]
        for j in range(n_hidden):
            r[j] = 1.0 / (1.0 + np.exp(-(gi[j] + gh[j])))
            z[j] = 1.0 / (1.0 + np.exp(-(gi[n_hidden + j] + gh[n_hidden + j])))
        for j in range(n_hidden):
            n[j] = np.tanh(gi[2 * n_hidden + j] + r[j] * gh[2 * n_hidden + j])
        for j in range(n_hidden):
            h[j] = (1.0 - z[j]) * n[j] + z[j] * h[j]
    y = b_out
    for j in range(n_hidden):
        y += w_out[j] * h[j]
    return y


@numba.njit(cache=True)
def _batch_forward(windows, w_ih, w_hh, b_ih, b_hh, w_out, b_out):  # type: ignore[no-untyped-def]  # pragma: no cover
    out = np.empty(windows.shape[0])
    for i in range(windows.shape[0]):
        out[i] = _window_forward(windows[i], w_ih, w_hh, b_ih, b_hh, w_out, b_out)
    return out


@dataclass(frozen=True)
class GruModel:
    """A trained compensator: weights, standardisation and window length."""

    weights: GruWeights
    standardisation: Standardisation
    window: int
    target: str = "residual"
    """`residual` (eq. 3: learns F_ref - F_physics) or `direct` (learns F_ref)."""

    def predict_window(self, window_std: Float2D) -> float:
        """Output (N) for one standardised window of shape (T, 3)."""
        w = self.weights
        y = _window_forward(window_std, w.w_ih, w.w_hh, w.b_ih, w.b_hh, w.w_out, w.b_out)
        s = self.standardisation
        return y * s.target_std + s.target_mean

    def predict(self, features: Float2D) -> Float1D:
        """Outputs (N) for every full window of `features` (n, 3): shape (n - T + 1,)."""
        windows = np.ascontiguousarray(
            make_windows(self.standardisation.features(features), self.window)
        )
        w = self.weights
        y = _batch_forward(windows, w.w_ih, w.w_hh, w.b_ih, w.b_hh, w.w_out, w.b_out)
        s = self.standardisation
        return y * s.target_std + s.target_mean


def make_windows(features: Float2D, window: int) -> Float3D:
    """All windows of `window` consecutive rows: shape (n - window + 1, window, 3)."""
    if len(features) < window:
        raise TeleopInputError(f"{len(features)} samples; expected at least the window of {window}")
    return sliding_window_view(features, (window, features.shape[1]))[:, 0]


def block_split(
    n_windows: int, window: int, config: GruConfig, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Indices of training and validation windows, split by contiguous time block.

    Window i covers samples i .. i + window - 1. Samples are cut into `config.blocks`
    blocks; a seeded choice of blocks (the validation fraction of them) validates.
    A window is used only if all its samples lie in blocks of one kind.
    """
    n_samples = n_windows + window - 1
    block_of_sample = np.minimum(
        np.arange(n_samples) * config.blocks // n_samples, config.blocks - 1
    )
    n_val = max(1, round(config.blocks * config.validation_fraction))
    rng = np.random.default_rng(seed)
    val_blocks = rng.choice(config.blocks, size=n_val, replace=False)
    # Validation samples inside each window: cumulative sums give them in O(n).
    in_val = np.concatenate(([0], np.cumsum(np.isin(block_of_sample, val_blocks))))
    val_count = in_val[window:] - in_val[:-window]
    train = np.flatnonzero(val_count == 0)
    val = np.flatnonzero(val_count == window)
    if len(train) == 0 or len(val) == 0:
        raise TeleopInputError(
            f"{n_samples} samples are too few to split into {config.blocks} blocks of "
            f"windows of {window}; expected a longer recording"
        )
    return train, val


@dataclass
class TrainingHistory:
    train_rmse: list[float] = field(default_factory=list)
    val_rmse: list[float] = field(default_factory=list)
    best_epoch: int = 0

    @property
    def best_val_rmse(self) -> float:
        return self.val_rmse[self.best_epoch - 1]


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
    progress: Callable[[int, float, float], None] | None = None,
) -> tuple[GruModel, TrainingHistory, np.ndarray, np.ndarray]:
    """Train the compensator on per-sample `features` (n, 3) and `target` (n,), N.

    The target of window i is the value at its last sample. `split` gives the training
    and validation window indices (default: `block_split` with `seed`). Returns the
    model at the best validation epoch, the history (RMSE in N per epoch), and the
    indices of the training and validation windows.
    """
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

    net = GruNet(config.hidden_size, config.dropout)
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
    model = GruModel(GruWeights.from_net(net), std, T, target_kind)
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
    progress: Callable[[int, float, float], None] | None,
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
        if progress is not None:
            progress(epoch, train_rmse, val_rmse)
        if config.patience is not None and epoch - history.best_epoch >= config.patience:
            break
    return history, best_state


def save_weights(model: GruModel, path: str) -> None:
    """Save the weights as a PyTorch state dict (loadable into `GruNet`)."""
    torch.save(model.weights.to_state_dict(), path)


def load_weights(path: str) -> GruWeights:
    return GruWeights.from_state_dict(torch.load(path, weights_only=True))
