"""Shape-typed aliases for the arrays the core passes around (one place, as pysindy does)."""

from typing import TypeAlias

import numpy as np
import numpy.typing as npt

Float1D: TypeAlias = npt.NDArray[np.float64]
"""A 1-D float64 array, shape (n,)."""
Float2D: TypeAlias = npt.NDArray[np.float64]
"""A 2-D float64 array, shape (n, m)."""
Float3D: TypeAlias = npt.NDArray[np.float64]
"""A 3-D float64 array, shape (n, t, m)."""
Int1D: TypeAlias = npt.NDArray[np.intp]
"""A 1-D array of indices, shape (n,)."""
Bool1D: TypeAlias = npt.NDArray[np.bool_]
"""A 1-D mask, shape (n,)."""
Rows: TypeAlias = slice | Int1D
"""Rows of a recording: a contiguous slice or an index array (blocked hold-out)."""
