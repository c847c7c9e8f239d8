"""The calibration figures: the training and held-out blocks over
time, and the held-out residual against the quantity REPORT.json's `unexplained` names."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pytest

from study.analysis.calibration_figures import (
    CAL_STYLE,
    held_out_mask,
    overview_figures,
    quantity_label,
    residual_against_unexplained,
    residual_blocks,
)
from teleop_core.calibration.verdict import quantities, unexplained


def _held_out_residual_over_speed(seed: int = 0) -> tuple[dict, np.ndarray, np.ndarray]:
    """Held-out signals whose residual is a friction left in the speed band."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, 0.005)
    speed = 2.0 * np.sin(2 * np.pi * 0.2 * t) + 0.5 * np.sin(2 * np.pi * 0.53 * t)
    angle = np.cumsum(speed) * 0.005
    residual = 0.05 * np.tanh(np.abs(speed) / 0.3) + rng.normal(0.0, 0.01, len(t))
    signals = {"t": t, "speed": speed, "angle": angle}
    return signals, residual, np.full(len(t), 1.0)


def test_unexplained_figure_is_drawn_against_the_named_quantity() -> None:
    signals, residual, prediction = _held_out_residual_over_speed()
    where = unexplained(residual, signals, prediction)
    assert where["quantity"] == "speed band"
    x = quantities(signals, prediction)[where["quantity"]]
    label = quantity_label(where["quantity"], "follower")
    assert label == "|wheel speed| (rad/s)"
    with plt.rc_context(CAL_STYLE):
        ax = residual_against_unexplained(x, residual, where, label)
    assert ax.get_xlabel() == label
    # the points are the residual over the quantity as the verdict binned it
    points = ax.collections[0].get_offsets()
    np.testing.assert_allclose(points[:, 0], x)
    np.testing.assert_allclose(points[:, 1], residual)
    # one line segment per bin of the report, at its mean
    means = ax.collections[1].get_segments()
    assert len(means) == len(where["bins"])
    assert [s[0][1] for s in means] == pytest.approx([b["mean_residual"] for b in where["bins"]])
    # every text at 8 pt or more
    texts = [ax.xaxis.label, ax.yaxis.label, ax.title, *ax.get_xticklabels(), *ax.get_yticklabels()]
    assert min(t.get_fontsize() for t in texts) >= 8
    plt.close(ax.figure)


@pytest.mark.parametrize(
    ("name", "model", "label"),
    [
        ("time window", "follower", "time (s)"),
        ("drive", "follower", "q-axis current (A)"),
        ("distance since reversal", "follower", "distance since the last reversal (rad)"),
        ("speed band", "rigid-axis", "|velocity q'| (m/s or rad/s)"),
        ("load", "notes-rotation", "load: |predicted output| (N m)"),
        ("temperature", "rigid-axis", "temperature (recorded units)"),
    ],
)
def test_quantity_labels_carry_units(name: str, model: str, label: str) -> None:
    unit = "N m" if model == "notes-rotation" else "N"
    assert quantity_label(name, model, unit) == label


def test_blocks_figure_shades_the_held_out_blocks() -> None:
    t = np.arange(0.0, 10.0, 0.01)
    # blocked hold-out: the end of each of two segments
    held = held_out_mask(len(t), np.r_[np.arange(400, 500), np.arange(900, 1000)])
    rng = np.random.default_rng(1)
    before, after = rng.normal(0, 0.2, len(t)), rng.normal(0, 0.05, len(t))
    with plt.rc_context(CAL_STYLE):
        axes = residual_blocks(t, before, after, held)
    for ax in axes:
        # axvspan draws a Rectangle in data x, axes y
        spans = sorted((p.get_x(), p.get_x() + p.get_width()) for p in ax.patches)
        assert spans == [pytest.approx((4.0, 4.99)), pytest.approx((9.0, 9.99))]
    labels = sorted(x.get_text() for x in axes[0].texts)
    assert labels == ["held out", "held out", "training", "training"]
    assert "held out 0.05" in axes[1].get_title(loc="left")
    plt.close(axes[0].figure)


def test_overview_writes_the_unexplained_figure_only_when_structure_remains(
    tmp_path: Path,
) -> None:
    signals, residual, prediction = _held_out_residual_over_speed()
    t = signals["t"]
    held = held_out_mask(len(t), slice(len(t) // 2, len(t)))
    where = unexplained(residual[held], {k: v[held] for k, v in signals.items()}, prediction[held])
    x = quantities({k: v[held] for k, v in signals.items()}, prediction[held])[where["quantity"]]
    remains = {"verdict": "structure_remains", "unexplained": where}
    (tmp_path / "a").mkdir()
    written = overview_figures(
        tmp_path / "a", t, residual + 0.1, residual, held, remains, x, "follower"
    )
    assert {p.name for p in written} == {"residual_blocks.png", "residual_vs_unexplained.png"}
    assert all(p.stat().st_size > 10_000 for p in written)
    (tmp_path / "b").mkdir()
    white = {"verdict": "white", "unexplained": None}
    written = overview_figures(tmp_path / "b", t, residual, residual, held, white, None, "follower")
    assert [p.name for p in written] == ["residual_blocks.png"]


def test_many_blocks_are_named_by_a_legend() -> None:
    # a NOTES chirp's blocked hold-out: the end of each of 8 segments
    t = np.arange(0.0, 16.0, 0.01)
    ends = range(200, 1601, 200)
    held = held_out_mask(len(t), np.concatenate([np.arange(s - 50, s) for s in ends]))
    e = np.random.default_rng(2).normal(0, 0.1, len(t))
    with plt.rc_context(CAL_STYLE):
        axes = residual_blocks(t, e, e, held)
    assert len(axes[0].patches) == 8
    assert len(axes[0].texts) == 0
    legend = axes[0].get_legend()
    assert [x.get_text() for x in legend.get_texts()] == ["held out", "training"]
    plt.close(axes[0].figure)
