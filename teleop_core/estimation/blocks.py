"""Blocked validation: a recording cut into contiguous time blocks, and the GRU windows
that lie wholly inside training blocks or wholly inside validation blocks (both the
plain split of `gru.py` and the regime-balanced one of `regimes.py` use these)."""

from __future__ import annotations

import numpy as np

from teleop_core.errors import TeleopInputError


def sample_blocks(n_samples: int, blocks: int) -> np.ndarray:
    """The block of each of `n_samples` samples cut into `blocks` contiguous blocks."""
    return np.minimum(np.arange(n_samples) * blocks // n_samples, blocks - 1)


def windows_by_block(
    block_of: np.ndarray, val_blocks: np.ndarray, window: int, blocks: int
) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the training and the validation windows: window i covers samples
    i .. i + window - 1 and is used only if all its samples lie in blocks of one kind."""
    # Validation samples inside each window: cumulative sums give them in O(n).
    in_val = np.concatenate(([0], np.cumsum(np.isin(block_of, val_blocks))))
    val_count = in_val[window:] - in_val[:-window]
    train = np.flatnonzero(val_count == 0)
    val = np.flatnonzero(val_count == window)
    if len(train) == 0 or len(val) == 0:
        raise TeleopInputError(
            f"{len(block_of)} samples are too few to split into {blocks} blocks of "
            f"windows of {window}; expected a longer recording"
        )
    return train, val
