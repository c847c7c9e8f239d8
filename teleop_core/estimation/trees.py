"""The trees residual stage: gradient-boosted regression trees in place of the GRU.

The same inputs as the GRU (`gru.py`): the last T samples of [I_q, theta_d, theta_dd]
and the memory features (`memory.py`), standardised with the training blocks' means and
SDs, here flattened to one row of T x inputs per window; the same target, eq. 1's
residual r_t = F_ref,t - F_physics,t. scikit-learn's `HistGradientBoostingRegressor`
fits it (its own early stopping on a random tenth of the training windows); the
fitted trees are then kept as plain arrays (`trees.npz`) and run by a small numba
kernel, so that running a model needs neither scikit-learn's pickles nor scikit-learn
at all, as the GRU's `gru.npz` needs no PyTorch. A test holds the kernel to
scikit-learn's own prediction.

A trees model runs over recordings (`ForceEstimator.predict`); the loop's compiled
kernel runs the GRU only, so `ForceEstimator.check_streams` refuses a trees model in
one line.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from teleop_core._jit import njit
from teleop_core._typing import Float1D, Float2D
from teleop_core.errors import TeleopInputError
from teleop_core.estimation.gru import N_FEATURES, Standardisation, make_windows
from teleop_core.estimation.memory import MemorySpec, memory_inputs

_ARRAY_NAMES = ("feature", "threshold", "left", "right", "is_leaf", "missing_left", "value")


@dataclass(frozen=True)
class TreesConfig:
    """Settings of the boosted trees (scikit-learn's defaults but for the iteration cap)."""

    max_iter: int = 300
    """Most boosting iterations (early stopping usually ends sooner)."""
    learning_rate: float = 0.1
    max_leaf_nodes: int = 31

    def __post_init__(self) -> None:
        for name in ("max_iter", "max_leaf_nodes"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 2 - (name == "max_iter"):
                raise TeleopInputError(f"TreesConfig.{name} = {value!r}; expected an integer")
        if not self.learning_rate > 0:
            raise TeleopInputError(
                f"TreesConfig.learning_rate = {self.learning_rate!r}; expected > 0"
            )


@dataclass(frozen=True)
class TreeArrays:
    """Every tree's nodes laid end to end; tree k's root is node `roots[k]`, and its
    children's indices are absolute. The prediction is `baseline` plus one leaf value
    per tree (scikit-learn's leaf values already carry the learning rate)."""

    feature: np.ndarray
    threshold: Float1D
    left: np.ndarray
    right: np.ndarray
    is_leaf: np.ndarray
    missing_left: np.ndarray
    value: Float1D
    roots: np.ndarray
    baseline: float

    @classmethod
    def from_sklearn(cls, model: Any) -> TreeArrays:
        """From a fitted single-output `HistGradientBoostingRegressor` (numeric features)."""
        parts: dict[str, list[np.ndarray]] = {name: [] for name in _ARRAY_NAMES}
        roots = []
        offset = 0
        for (predictor,) in model._predictors:
            nodes = predictor.nodes
            if np.any(nodes["is_categorical"]):  # pragma: no cover - numeric inputs only
                raise TeleopInputError("categorical splits; expected numeric inputs only")
            roots.append(offset)
            parts["feature"].append(nodes["feature_idx"].astype(np.int64))
            parts["threshold"].append(nodes["num_threshold"].astype(np.float64))
            parts["left"].append(nodes["left"].astype(np.int64) + offset)
            parts["right"].append(nodes["right"].astype(np.int64) + offset)
            parts["is_leaf"].append(nodes["is_leaf"].astype(np.bool_))
            parts["missing_left"].append(nodes["missing_go_to_left"].astype(np.bool_))
            parts["value"].append(nodes["value"].astype(np.float64))
            offset += len(nodes)
        return cls(
            **{name: np.concatenate(parts[name]) for name in _ARRAY_NAMES},
            roots=np.asarray(roots, dtype=np.int64),
            baseline=float(np.ravel(model._baseline_prediction)[0]),
        )

    def predict(self, x: Float2D) -> Float1D:
        """The sum over trees for every row of `x` (n, columns)."""
        return _predict_trees(
            np.ascontiguousarray(x, dtype=np.float64),
            self.feature,
            self.threshold,
            self.left,
            self.right,
            self.is_leaf,
            self.missing_left,
            self.value,
            self.roots,
            self.baseline,
        )


@njit(cache=True)
def _predict_trees(  # pragma: no cover
    x, feature, threshold, left, right, is_leaf, missing_left, value, roots, baseline
):
    out = np.full(x.shape[0], baseline)
    for i in range(x.shape[0]):
        acc = 0.0
        for k in range(roots.shape[0]):
            node = roots[k]
            while not is_leaf[node]:
                v = x[i, feature[node]]
                if np.isnan(v):
                    node = left[node] if missing_left[node] else right[node]
                elif v <= threshold[node]:
                    node = left[node]
                else:
                    node = right[node]
            acc += value[node]
        out[i] += acc
    return out


@dataclass(frozen=True)
class TreesModel:
    """A trained trees compensator: the trees, the inputs' standardisation, the window.

    The same face as `GruModel` (`inputs`, `predict`, `window`, `memory`, `target`), so
    `ForceEstimator` runs either."""

    trees: TreeArrays
    standardisation: Standardisation
    window: int
    target: str = "residual"
    memory: MemorySpec = field(default_factory=MemorySpec.none)

    def inputs(self, t: Float1D, base: Float2D) -> Float2D:
        """Per-sample inputs from times `t` (n,) and [I_q, theta_d, theta_dd] (n, 3)."""
        return memory_inputs(t, base, self.memory)

    @property
    def n_inputs(self) -> int:
        return N_FEATURES + self.memory.n_features

    def rows(self, features: Float2D) -> Float2D:
        """One flattened standardised window per full window of `features`."""
        if features.ndim != 2 or features.shape[1] != self.n_inputs:
            raise TeleopInputError(
                f"inputs of shape {features.shape}; expected (n, {self.n_inputs})"
            )
        w = make_windows(self.standardisation.features(features), self.window)
        return w.reshape(len(w), -1)

    def predict(self, features: Float2D) -> Float1D:
        """Residual (N) for every full window of `features`: shape (n - T + 1,)."""
        return self.trees.predict(self.rows(features))

    def save_npz(self, path: Path) -> None:
        arrays = {name: getattr(self.trees, name) for name in (*_ARRAY_NAMES, "roots")}
        with open(path, "wb") as f:
            np.savez(f, baseline=np.float64(self.trees.baseline), **arrays)

    @staticmethod
    def load_trees(path: Path) -> TreeArrays:
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: np.asarray(data[name]) for name in (*_ARRAY_NAMES, "roots")}
                baseline = float(data["baseline"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise TeleopInputError(
                f"{path}: {exc}; expected the trees written by `study estimator train`"
            ) from None
        n = len(arrays["value"])
        if any(len(arrays[name]) != n for name in _ARRAY_NAMES) or (
            n
            and (
                arrays["roots"].max() >= n or max(arrays["left"].max(), arrays["right"].max()) >= n
            )
        ):
            raise TeleopInputError(f"{path}: node arrays disagree in length or index; damaged")
        return TreeArrays(
            feature=arrays["feature"].astype(np.int64),
            threshold=arrays["threshold"].astype(np.float64),
            left=arrays["left"].astype(np.int64),
            right=arrays["right"].astype(np.int64),
            is_leaf=arrays["is_leaf"].astype(np.bool_),
            missing_left=arrays["missing_left"].astype(np.bool_),
            value=arrays["value"].astype(np.float64),
            roots=arrays["roots"].astype(np.int64),
            baseline=baseline,
        )


def train_trees(
    inputs: Float2D,
    residual: Float1D,
    window: int,
    memory: MemorySpec,
    train_idx: np.ndarray,
    config: TreesConfig | None = None,
    seed: int = 0,
) -> TreesModel:
    """Fit the trees to `residual` on the training windows `train_idx` (window i ends at
    sample i + window - 1); the standardisation comes from those windows' samples."""
    # lazy: sklearn.ensemble costs 1.2 s at start-up
    from sklearn.ensemble import HistGradientBoostingRegressor

    config = config or TreesConfig()
    samples = np.unique((train_idx[:, None] + np.arange(window)).ravel())
    std = Standardisation.fit(inputs[samples], residual[samples])
    std = Standardisation(std.feature_mean, std.feature_std, 0.0, 1.0)
    empty = {name: np.zeros(0) for name in (*_ARRAY_NAMES, "roots")}
    shell = TreesModel(TreeArrays(**empty, baseline=0.0), std, window, memory=memory)
    x = shell.rows(inputs)[train_idx]
    y = residual[window - 1 :][train_idx]
    fitted = HistGradientBoostingRegressor(
        max_iter=config.max_iter,
        learning_rate=config.learning_rate,
        max_leaf_nodes=config.max_leaf_nodes,
        early_stopping=True,
        random_state=seed,
    ).fit(x, y)
    return TreesModel(TreeArrays.from_sklearn(fitted), std, window, memory=memory)
