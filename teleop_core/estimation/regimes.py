"""Operating regimes of a follower recording, and a validation split that represents them.

A network validated on blocks that hold little of what it must learn picks the epoch
that learned nothing (two random blocks out of ten can hold a fraction of the
training blocks' physics error). So every sample gets a label in three dimensions:

- speed: `rest`, `slow`, `fast`, `reversal`. `reversal`: speeds of both signs beyond
  `rest_speed_rad_s` within `reversal_window_s`; else by abs(theta_d): below
  `rest_speed_rad_s`, below `slow_speed_rad_s`, above;
- direction: `forward`, `backward`, `none`: the sign of theta_d beyond
  `rest_speed_rad_s`;
- load: `low`, `mid`, `high`: abs(F_ref) against its tertiles over the training
  recording;

and `representative_split` chooses, among seeded candidate sets of contiguous time
blocks, the validation blocks whose mixture of labels is closest to the whole
recording's, with every label that the recording holds in both training and validation
(if any candidate manages it). `regime_rmse` gives the error per label.

The search is a few thousand candidate subsets of about twenty blocks scored on their
label counts (milliseconds); an exact stratified optimiser would add a dependency for no
gain at this size. scikit-learn's `StratifiedGroupKFold` stratifies one label per
sample, not three, and would not keep the blocks' boundaries at the window's scale.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TypedDict

import numpy as np
from scipy.ndimage import maximum_filter1d

from teleop_core._typing import Float1D
from teleop_core.errors import TeleopInputError
from teleop_core.estimation.blocks import sample_blocks, windows_by_block
from teleop_core.estimation.metrics import rmse

SPEED = ("rest", "slow", "fast", "reversal")
DIRECTION = ("forward", "backward", "none")
LOAD = ("low", "mid", "high")
LABELS = (
    tuple(f"speed:{s}" for s in SPEED)
    + tuple(f"direction:{d}" for d in DIRECTION)
    + tuple(f"load:{ld}" for ld in LOAD)
)
"""Every regime label, as the summaries name them."""
DIMENSIONS = 3
"""Speed, direction, load: each sample carries one label of each."""


@dataclass(frozen=True)
class RegimeRules:
    """Thresholds of the regime labels (SI)."""

    rest_speed_rad_s: float = 0.05
    """Below this speed the wheel is at rest (as the EKF's rest-noise rule)."""
    slow_speed_rad_s: float = 1.5
    """Below this speed motion is slow (a Stribeck dip lies below ~1.5 rad/s)."""
    reversal_window_s: float = 0.25
    """Speeds of both signs within this span make a reversal."""
    load_low_n: float = 0.0
    """abs(F_ref) up to this is a low load (the lower tertile of the training data)."""
    load_high_n: float = 0.0
    """abs(F_ref) above this is a high load (the upper tertile)."""

    def __post_init__(self) -> None:
        if not 0 < self.rest_speed_rad_s < self.slow_speed_rad_s:
            raise TeleopInputError(
                f"rest speed {self.rest_speed_rad_s!r} and slow speed "
                f"{self.slow_speed_rad_s!r} rad/s; expected 0 < rest < slow"
            )
        if not self.reversal_window_s > 0 or self.load_high_n < self.load_low_n:
            raise TeleopInputError(
                f"reversal window {self.reversal_window_s!r} s, loads {self.load_low_n!r} / "
                f"{self.load_high_n!r} N; expected a window > 0 and low <= high"
            )

    @classmethod
    def for_loads(cls, f_ref: Float1D) -> RegimeRules:
        """Default speeds, load levels at the tertiles of abs(`f_ref`) (N)."""
        low, high = np.quantile(np.abs(f_ref), [1 / 3, 2 / 3])
        return cls(load_low_n=float(low), load_high_n=float(high))

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def label_samples(
    omega: Float1D, f_ref: Float1D, rate_hz: float, rules: RegimeRules
) -> dict[str, np.ndarray]:
    """Boolean masks, one per label of `LABELS`, over the samples (speeds rad/s, forces N)."""
    omega = np.asarray(omega, float)
    moving = np.abs(omega) >= rules.rest_speed_rad_s
    span = max(1, round(rules.reversal_window_s * rate_hz))
    fwd = np.where(omega > rules.rest_speed_rad_s, 1.0, 0.0)
    bwd = np.where(omega < -rules.rest_speed_rad_s, 1.0, 0.0)
    reversal = (maximum_filter1d(fwd, span) > 0) & (maximum_filter1d(bwd, span) > 0)
    speed = np.abs(omega)
    load = np.abs(np.asarray(f_ref, float))
    masks = {
        "speed:reversal": reversal,
        "speed:rest": ~reversal & ~moving,
        "speed:slow": ~reversal & moving & (speed < rules.slow_speed_rad_s),
        "speed:fast": ~reversal & (speed >= rules.slow_speed_rad_s),
        "direction:forward": omega > rules.rest_speed_rad_s,
        "direction:backward": omega < -rules.rest_speed_rad_s,
        "direction:none": ~moving,
        "load:low": load <= rules.load_low_n,
        "load:mid": (load > rules.load_low_n) & (load <= rules.load_high_n),
        "load:high": load > rules.load_high_n,
    }
    return {label: masks[label] for label in LABELS}


def _block_counts(masks: dict[str, np.ndarray], block_of: np.ndarray, blocks: int) -> np.ndarray:
    """Samples of each label in each block: shape (blocks, len(LABELS))."""
    return np.column_stack(
        [np.bincount(block_of[masks[label]], minlength=blocks) for label in LABELS]
    ).astype(float)


class RegimeShares(TypedDict):
    """A label's share of the samples: of all, of the training windows', of the
    validation windows' (by their last sample)."""

    all: float
    train: float
    validation: float


class SplitReport(TypedDict):
    """`representative_split`'s account of its choice."""

    validation_blocks: list[int]
    blocks: int
    share: dict[str, RegimeShares]
    missing: list[str]
    """Each label (of at least the minimum share) absent from a part, as `label (part)`."""


def representative_split(
    masks: dict[str, np.ndarray],
    n_windows: int,
    window: int,
    blocks: int,
    validation_fraction: float,
    seed: int,
    candidates: int = 4000,
    min_share: float = 0.01,
) -> tuple[np.ndarray, np.ndarray, SplitReport]:
    """Training and validation window indices from contiguous blocks that represent the regimes.

    Window i covers samples i .. i + window - 1 and its label is its last sample's.
    Labels holding at least `min_share` of the samples must appear in both parts;
    among the seeded candidates that manage it (all candidates if none does), the one
    whose validation mixture deviates least from the whole recording's (largest
    relative difference over those labels) wins. Returns the two index arrays and a
    report: the blocks chosen, each label's share overall and in each part, and any
    label missing from a part.
    """
    n_samples = n_windows + window - 1
    if not 0 < validation_fraction < 1:
        raise TeleopInputError(
            f"validation_fraction {validation_fraction!r}; expected between 0 and 1"
        )
    block_of = sample_blocks(n_samples, blocks)
    counts = _block_counts(masks, block_of, blocks)
    total = counts.sum(axis=0)
    share = total / n_samples
    needed = share >= min_share
    n_val = max(1, round(blocks * validation_fraction))
    rng = np.random.default_rng(seed)
    # Candidate validation sets as rows of a 0/1 matrix over the blocks: their label
    # counts are one matrix product.
    chosen = np.argsort(rng.random((candidates, blocks)), axis=1)[:, :n_val]
    member = np.zeros((candidates, blocks))
    np.put_along_axis(member, chosen, 1.0, axis=1)
    val = member @ counts
    train = total - val
    missing = np.sum(needed & ((val == 0) | (train == 0)), axis=1)
    val_share = val / np.maximum(val.sum(axis=1, keepdims=True) / DIMENSIONS, 1.0)
    deviation = np.max(
        np.abs(val_share[:, needed] - share[needed]) / share[needed], axis=1, initial=0.0
    )
    best = np.lexsort((deviation, missing))[0]  # fewest labels missing, then closest
    val_blocks = np.sort(chosen[best])
    train_idx, val_idx = windows_by_block(block_of, val_blocks, window, blocks)
    last = np.arange(window - 1, n_samples)
    report: SplitReport = {
        "validation_blocks": val_blocks.tolist(),
        "blocks": blocks,
        "share": {
            label: {
                "all": float(share[k]),
                "train": float(masks[label][last[train_idx]].mean()),
                "validation": float(masks[label][last[val_idx]].mean()),
            }
            for k, label in enumerate(LABELS)
        },
        "missing": [
            f"{label} ({part})"
            for k, label in enumerate(LABELS)
            if needed[k]
            for part, rows in (("train", train_idx), ("validation", val_idx))
            if not masks[label][last[rows]].any()
        ],
    }
    return train_idx, val_idx, report


def regime_rmse(
    masks: dict[str, np.ndarray], truth: Float1D, **estimates: Float1D
) -> dict[str, dict[str, float]]:
    """RMSE (N) of each estimate per label, with the label's sample count; labels with no
    sample are left out. `masks`, `truth` and the estimates share one length."""
    out: dict[str, dict[str, float]] = {}
    for label in LABELS:
        rows = masks[label]
        if not rows.any():
            continue
        row: dict[str, float] = {"samples": int(rows.sum())}
        for name, values in estimates.items():
            row[name] = rmse(np.asarray(values)[rows], np.asarray(truth)[rows])
        out[label] = row
    return out
