"""The trees residual stage (`estimation/trees.py`): its kernel against scikit-learn's own
prediction, its file round trip, and a trees model refused by the loop's stream."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.estimation.gru import Standardisation
from teleop_core.estimation.memory import MemorySpec
from teleop_core.estimation.trees import TreeArrays, TreesModel


def _fitted(seed: int = 0):  # type: ignore[no-untyped-def]
    from sklearn.ensemble import HistGradientBoostingRegressor

    rng = np.random.default_rng(seed)
    x = rng.normal(size=(600, 4))
    y = np.sin(2 * x[:, 0]) + np.where(x[:, 1] > 0.3, 0.5, -0.2) + 0.05 * rng.normal(size=600)
    model = HistGradientBoostingRegressor(max_iter=40, random_state=seed).fit(x, y)
    return model, rng.normal(size=(200, 4))


def test_the_kernel_predicts_what_scikit_learn_predicts() -> None:
    model, x = _fitted()
    trees = TreeArrays.from_sklearn(model)
    assert len(trees.roots) == model.n_iter_
    np.testing.assert_allclose(trees.predict(x), model.predict(x), rtol=0, atol=1e-12)


def test_the_trees_survive_their_file(tmp_path: Path) -> None:
    from sklearn.ensemble import HistGradientBoostingRegressor

    x = np.random.default_rng(1).normal(size=(300, 4))
    # a window of 1 over [I_q, theta_d, theta_dd]: three columns, unscaled
    three = HistGradientBoostingRegressor(max_iter=20, random_state=0).fit(x[:, :3], x[:, 3])
    std = Standardisation((0.0,) * 3, (1.0,) * 3, 0.0, 1.0)
    saved = TreesModel(TreeArrays.from_sklearn(three), std, window=1, memory=MemorySpec.none())
    saved.save_npz(tmp_path / "trees.npz")
    loaded = TreesModel(TreesModel.load_trees(tmp_path / "trees.npz"), std, 1)
    # summed in another order than scikit-learn's: rounding only
    np.testing.assert_allclose(loaded.predict(x[:, :3]), three.predict(x[:, :3]), atol=1e-12)
    (tmp_path / "bad.npz").write_bytes(b"not an archive")
    with pytest.raises(TeleopInputError, match=r"bad\.npz"):
        TreesModel.load_trees(tmp_path / "bad.npz")
