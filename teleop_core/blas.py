"""BLAS on one thread around work made of many small matrix products.

The numerics' linear algebra (the calibration loop's least squares, the participant
fit's ridge regressions, eigendecompositions and small solves) is thousands of products
and factorisations of matrices with tens of columns: a second BLAS thread gains little
on them, and on a machine whose cores are busy with other work (or with the fit's own
simulation workers) its threads wait for each other in spin loops that cost more CPU
time than the products themselves. OpenBLAS splits a product's output between its
threads, each element summed by one thread in the same order, so the results do not
depend on the thread count (the participant fit's tests hold MODEL.json equal).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

_P = ParamSpec("_P")
_R = TypeVar("_R")


def one_blas_thread(func: Callable[_P, _R]) -> Callable[_P, _R]:
    """`func` run with the BLAS libraries (OpenBLAS under numpy and scipy) on one
    thread; the limit (`threadpoolctl`) is lifted again when `func` returns."""

    @functools.wraps(func)
    def limited(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        # lazy: threadpoolctl costs 13 ms at start-up
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return limited
