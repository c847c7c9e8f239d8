"""The GRU stage: a sequence-to-one GRU over the last T samples of [I_q, theta_d, theta_dd]
and, by default, their memory features (`memory.py`: each input minus its moving
averages, which carry what happened before the window).

Training (PyTorch) follows [endovascular], eqs. 3-4 and 12-13: the residual compensator
learns r_t = F_ref,t - F_physics,t (eq. 13) by minimising the mean squared error of
eq. 12, with Adam, lr 1e-4, batch 32, up to 100 epochs, on standardised inputs; the
checkpoint with the lowest validation RMSE is kept. The split is by contiguous time
block (windows that straddle a train/validation boundary are dropped), never by
random samples, so validation windows share no samples with training windows. The
direct variant (Table III) learns F_ref itself with the same network.

Inference does not use PyTorch, and this module does not import it (1.7-4 s of a fresh
process's start): the weights are saved at training time as plain arrays (`gru.npz`,
`GruWeights.save_npz`) beside PyTorch's `gru.pt`, and run through a small numba kernel
in float32, the precision PyTorch trains and runs the network in (the weights it
trains are float32 values, so they convert exactly), with the weights transposed so
that each matrix-vector product runs down contiguous columns and sigma and tanh through
a vectorised rational tanh (`_window_forward`). The plain float64 form with libm's
functions, `_window_forward_libm`, is what the loop ran before; tests hold the float32
kernel to torch's own float32 GRU and the loop's samples to that older path within
stated tolerances. Inference is what lets the estimator sit inside a 1 kHz simulation
loop, so its cost per window is measured in `benchmarks/loop_profile.py`.
The same compiled function serves one window (causal, sample by sample) and every
window of a recording (batch), so the two agree to the last bit. Training, and
everything else that needs PyTorch, is in `gru_torch.py`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from teleop_core._jit import njit
from teleop_core._typing import Float1D, Float2D, Float3D
from teleop_core.errors import TeleopInputError
from teleop_core.estimation.blocks import sample_blocks, windows_by_block
from teleop_core.estimation.memory import MemorySpec, memory_inputs

N_FEATURES = 3
"""[I_q, theta_d, theta_dd] per time step (the memory features come after them)."""


PATIENCE = 10
WEIGHT_DECAY = 1e-3
DROPOUT = 0.0
INPUT_NOISE = 0.0
"""Regularisation defaults. Not chosen by measurement: no alternative has been
run on the generalisation bench (`study bench follower --only generalisation`). What the
bench measured with them (README, Performance): the GRU carries a Stribeck dip and a
direction-dependent load over to unseen data, but at lr 1e-4 it is still improving at
epoch 100 there, and gradient-boosted trees on the same windows do better."""


@dataclass(frozen=True)
class GruConfig:
    """Network and training settings (defaults: [endovascular], IV-C)."""

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
    memory: MemorySpec = field(default_factory=MemorySpec)
    """Memory features appended to each time step's inputs (`MemorySpec.none()`: the
    paper's plain window). On by default: without them the GRU learned nothing that
    transfers for hysteresis."""

    @property
    def n_inputs(self) -> int:
        """GRU inputs per time step."""
        return N_FEATURES + self.memory.n_features

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


@dataclass(frozen=True)
class GruWeights:
    """A trained network in float64 numpy arrays (`kernel_weights`: the inference
    kernel's float32 form)."""

    w_ih: Float2D  # (3H, inputs), gates in torch's order r, z, n
    w_hh: Float2D  # (3H, H)
    b_ih: Float1D
    b_hh: Float1D
    w_out: Float1D  # (H,)
    b_out: float

    @classmethod
    def from_state_dict(cls, state: Mapping[str, Any]) -> GruWeights:
        """From a `GruNet` state dict (tensors of any dtype), as float64 contiguous arrays."""
        sd = {k: np.asarray(v.detach().cpu().double()) for k, v in state.items()}
        return cls(
            np.ascontiguousarray(sd["gru.weight_ih_l0"]),
            np.ascontiguousarray(sd["gru.weight_hh_l0"]),
            np.ascontiguousarray(sd["gru.bias_ih_l0"]),
            np.ascontiguousarray(sd["gru.bias_hh_l0"]),
            np.ascontiguousarray(sd["head.weight"][0]),
            float(sd["head.bias"][0]),
        )

    def save_npz(self, path: Path) -> None:
        """The weights as plain float64 arrays (`gru.npz`): what inference reads."""
        with open(path, "wb") as f:
            arrays = {name: np.asarray(getattr(self, name)) for name in _WEIGHT_NAMES}
            # numpy's stubs read any keyword of savez as its allow_pickle flag
            np.savez(f, **arrays)  # type: ignore[arg-type]

    def kernel_weights(self) -> tuple[Float2D, Float2D, Float1D, Float1D, Float1D, float]:
        """(w_ih_t, w_hh_t, b_ih, b_hh, w_out, b_out): the arguments `_window_forward`
        takes after the window, in float32 (the precision PyTorch trains the network in,
        so that weights trained there convert exactly), the matrices transposed and
        contiguous."""
        return (
            np.ascontiguousarray(self.w_ih.T, dtype=np.float32),
            np.ascontiguousarray(self.w_hh.T, dtype=np.float32),
            np.ascontiguousarray(self.b_ih, dtype=np.float32),
            np.ascontiguousarray(self.b_hh, dtype=np.float32),
            np.ascontiguousarray(self.w_out, dtype=np.float32),
            float(np.float32(self.b_out)),
        )

    @property
    def n_inputs(self) -> int:
        """Inputs per time step the network takes."""
        return int(self.w_ih.shape[1])

    @classmethod
    def load_npz(cls, path: Path) -> GruWeights:
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays: dict[str, Any] = {
                    name: np.ascontiguousarray(data[name], dtype=np.float64)
                    for name in _WEIGHT_NAMES[:-1]
                }
                arrays["b_out"] = float(data["b_out"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise TeleopInputError(
                f"{path}: {exc}; expected the GRU weights written by `study estimator train`"
            ) from None
        weights = cls(**arrays)
        hidden = weights.w_hh.shape[1] if weights.w_hh.ndim == 2 else -1
        inputs = weights.w_ih.shape[1] if weights.w_ih.ndim == 2 else -1
        shapes = {
            "w_ih": (3 * hidden, inputs),
            "w_hh": (3 * hidden, hidden),
            "b_ih": (3 * hidden,),
            "b_hh": (3 * hidden,),
            "w_out": (hidden,),
        }
        for name, shape in shapes.items():
            if getattr(weights, name).shape != shape:
                raise TeleopInputError(
                    f"{path}: {name} has shape {getattr(weights, name).shape}; expected {shape}"
                )
        return weights


_WEIGHT_NAMES = ("w_ih", "w_hh", "b_ih", "b_hh", "w_out", "b_out")


@njit(cache=True, fastmath={"reassoc", "contract", "arcp", "nsz", "afn"})
def _window_forward_libm(x, w_ih, w_hh, b_ih, b_hh, w_out, b_out):  # pragma: no cover
    # The reference form: torch's weight layout, libm's exp and tanh per unit. What the
    # loop ran before `_window_forward`; kept so that tests hold the two within a stated
    # tolerance of each other.
    # h' = (1 - z) n + z h, with r, z = sigma(W_i x + b_i + W_h h + b_h) and
    # n = tanh(W_in x + b_in + r (W_hn h + b_hn))   (torch.nn.GRU's equations)
    n_hidden = w_hh.shape[1]
    n_in = w_ih.shape[1]
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
            if n_in == 3:  # the plain window, summed as models before memory features were
                gi[j] = b_ih[j] + w_ih[j, 0] * x[t, 0] + w_ih[j, 1] * x[t, 1] + w_ih[j, 2] * x[t, 2]
            else:
                acc = b_ih[j]
                for k in range(n_in):
                    acc += w_ih[j, k] * x[t, k]
                gi[j] = acc
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


# tanh(x) ~ x P(x^2) / Q(x^2) on [-9, 9], P of degree 6 and Q of degree 3 in x^2: the
# float32 rational approximation of Eigen's generic_fast_tanh_float (Eigen 3.3-3.4,
# MathFunctionsImpl.h); within 3e-7 of tanh (a test checks it against numpy's float64
# tanh), while tanh(9) rounds to 1 in float32. Only multiply-adds, one division and a
# clamp: it vectorises, where libm's tanhf and expf are one call per value.
_F32 = np.float32
_TANH_CLAMP = _F32(9.0)
_TANH_P = tuple(
    _F32(c)
    for c in (
        -2.76076847742355e-16,
        2.00018790482477e-13,
        -8.60467152213735e-11,
        5.12229709037114e-08,
        1.48572235717979e-05,
        6.37261928875436e-04,
        4.89352455891786e-03,
    )
)
_TANH_Q = tuple(
    _F32(c)
    for c in (
        1.19825839466702e-06,
        1.18534705686654e-04,
        2.26843463243900e-03,
        4.89352518554385e-03,
    )
)
_HALF, _ONE = _F32(0.5), _F32(1.0)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _tanh32(x):  # pragma: no cover
    """tanh of a float32 within 3e-7 (the rational form above)."""
    x = min(max(x, -_TANH_CLAMP), _TANH_CLAMP)
    x2 = x * x
    p = _TANH_P[0]
    p = p * x2 + _TANH_P[1]
    p = p * x2 + _TANH_P[2]
    p = p * x2 + _TANH_P[3]
    p = p * x2 + _TANH_P[4]
    p = p * x2 + _TANH_P[5]
    p = p * x2 + _TANH_P[6]
    q = _TANH_Q[0]
    q = q * x2 + _TANH_Q[1]
    q = q * x2 + _TANH_Q[2]
    q = q * x2 + _TANH_Q[3]
    return x * p / q


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def _tanh32_into(v, out):  # pragma: no cover
    """out[j] = `_tanh32`(v[j]) (for tests of the approximation)."""
    for j in range(v.shape[0]):
        out[j] = _tanh32(v[j])


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def _window_forward(x, w_ih_t, w_hh_t, b_ih, b_hh, w_out, b_out):  # pragma: no cover
    """The GRU's output for one standardised window `x` (T, inputs), in float32 as the
    network was trained; weights as `GruWeights.kernel_weights` gives them (float32,
    transposed: w_ih_t (inputs, 3H), w_hh_t (H, 3H)).

    The equations of `_window_forward_libm` (torch.nn.GRU's), arranged for the vector
    unit: each product W h is a sum of the columns of W scaled by h's units (eight per
    pass over gh, no horizontal sums), the first step skips W_hh h (h = 0), and sigma and
    tanh come from `_tanh32` (sigma(a) = (1 + tanh(a / 2)) / 2). The inputs are rounded
    to float32 as torch rounds them. `error_model="numpy"`: a division by zero would give
    inf instead of raising (the divisors here are >= 1e-3), so the loops have no branch
    and vectorise. A test holds the output to torch's own float32 GRU.
    """
    n_hidden = w_hh_t.shape[0]
    n_in = w_ih_t.shape[0]
    n3 = 3 * n_hidden
    h = np.zeros(n_hidden, dtype=np.float32)
    gh = np.empty(n3, dtype=np.float32)
    gi = np.empty(n3, dtype=np.float32)
    for t in range(x.shape[0]):
        # gi = W_ih x + b_ih, gh = W_hh h + b_hh
        for j in range(n3):
            gi[j] = b_ih[j]
            gh[j] = b_hh[j]
        for k in range(n_in):
            xk = _F32(x[t, k])
            for j in range(n3):
                gi[j] += w_ih_t[k, j] * xk
        if t > 0:
            # eight columns per pass over gh: an eighth of its loads and stores
            k = 0
            while k + 8 <= n_hidden:
                h0, h1, h2, h3 = h[k], h[k + 1], h[k + 2], h[k + 3]
                h4, h5, h6, h7 = h[k + 4], h[k + 5], h[k + 6], h[k + 7]
                w0, w1, w2, w3 = w_hh_t[k], w_hh_t[k + 1], w_hh_t[k + 2], w_hh_t[k + 3]
                w4, w5, w6, w7 = w_hh_t[k + 4], w_hh_t[k + 5], w_hh_t[k + 6], w_hh_t[k + 7]
                for j in range(n3):
                    gh[j] += ((w0[j] * h0 + w1[j] * h1) + (w2[j] * h2 + w3[j] * h3)) + (
                        (w4[j] * h4 + w5[j] * h5) + (w6[j] * h6 + w7[j] * h7)
                    )
                k += 8
            while k < n_hidden:
                hk, wk = h[k], w_hh_t[k]
                for j in range(n3):
                    gh[j] += wk[j] * hk
                k += 1
        for j in range(n_hidden):
            # r, z = sigma(W_i x + b_i + W_h h + b_h); n = tanh(W_in x + b_in + r (W_hn h + b_hn))
            r = _HALF + _HALF * _tanh32(_HALF * (gi[j] + gh[j]))
            z = _HALF + _HALF * _tanh32(_HALF * (gi[n_hidden + j] + gh[n_hidden + j]))
            n = _tanh32(gi[2 * n_hidden + j] + r * gh[2 * n_hidden + j])
            # h' = (1 - z) n + z h
            h[j] = (_ONE - z) * n + z * h[j]
    y = _F32(b_out)
    for j in range(n_hidden):
        y += w_out[j] * h[j]
    return y


@njit(cache=True)
def _batch_forward(windows, w_ih_t, w_hh_t, b_ih, b_hh, w_out, b_out):  # pragma: no cover
    out = np.empty(windows.shape[0])
    for i in range(windows.shape[0]):
        out[i] = _window_forward(windows[i], w_ih_t, w_hh_t, b_ih, b_hh, w_out, b_out)
    return out


@dataclass(frozen=True)
class GruModel:
    """A trained compensator: weights, standardisation and window length."""

    weights: GruWeights
    standardisation: Standardisation
    window: int
    target: str = "residual"
    """`residual` (eq. 3: learns F_ref - F_physics) or `direct` (learns F_ref)."""
    memory: MemorySpec = field(default_factory=MemorySpec.none)
    """The memory features the network was trained with (`inputs` builds them)."""

    def __post_init__(self) -> None:
        expected = N_FEATURES + self.memory.n_features
        if self.weights.n_inputs != expected or len(self.standardisation.feature_mean) != expected:
            raise TeleopInputError(
                f"GRU weights take {self.weights.n_inputs} inputs per step and the "
                f"standardisation {len(self.standardisation.feature_mean)}; the memory "
                f"features ({self.memory.to_dict()['kind']}) give {expected}"
            )

    def inputs(self, t: Float1D, base: Float2D) -> Float2D:
        """Per-sample network inputs from times `t` (n,) and [I_q, theta_d, theta_dd] (n, 3)."""
        return memory_inputs(t, base, self.memory)

    def predict(self, features: Float2D) -> Float1D:
        """Outputs (N) for every full window of `features` (n, inputs), as `inputs` builds
        them: shape (n - T + 1,)."""
        if features.ndim != 2 or features.shape[1] != self.weights.n_inputs:
            raise TeleopInputError(
                f"inputs of shape {features.shape}; expected (n, {self.weights.n_inputs})"
            )
        windows = np.ascontiguousarray(
            make_windows(self.standardisation.features(features), self.window)
        )
        y = _batch_forward(windows, *self.weights.kernel_weights())
        s = self.standardisation
        return y * s.target_std + s.target_mean


def make_windows(features: Float2D, window: int) -> Float3D:
    """All windows of `window` consecutive rows: shape (n - window + 1, window, columns)."""
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
    block_of_sample = sample_blocks(n_samples, config.blocks)
    n_val = max(1, round(config.blocks * config.validation_fraction))
    rng = np.random.default_rng(seed)
    val_blocks = rng.choice(config.blocks, size=n_val, replace=False)
    return windows_by_block(block_of_sample, val_blocks, window, config.blocks)


@dataclass
class TrainingHistory:
    train_rmse: list[float] = field(default_factory=list)
    val_rmse: list[float] = field(default_factory=list)
    best_epoch: int = 0

    @property
    def best_val_rmse(self) -> float:
        return self.val_rmse[self.best_epoch - 1]
