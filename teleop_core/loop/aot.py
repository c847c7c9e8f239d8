"""The loop kernel compiled ahead of time into an extension module.

Through numba's on-disk cache a fresh process still imports numba and sets up its CPU
target before it can load the kernel: about 2 s of a 20 s trial's 2.5 s. The first
process that needs an environment's kernel therefore also compiles it with
`numba.pycc` into a C extension in the kernel cache folder (`kernel._cache_dir`,
named by the digest of the kernel's sources and numba's version), and later processes
import that module: no numba at all (`teleop_core._jit` defers its import).

The extension is compiled for this machine's CPU (`target_cpu = "host"`), as numba's
JIT compiles, so it computes what the JIT kernel computes, bit for bit (a test holds
them equal). Where it cannot be built (no C compiler, an unwritable folder) a marker
file says so, and the kernel runs through numba's cache as before. Its signature is
fixed (`signature`); a call whose argument types differ runs the JIT kernel instead.
numba.pycc's wrapper checks little of that itself (a tuple of another length, or an
array of another dtype, is read as if it were the signature's), so the tuple arguments
are checked here first (`check_arguments`).

numba.pycc is numba's own ahead-of-time compiler (deprecated in favour of a successor
that is not released yet); nothing else compiles a numba kernel ahead of time.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import tempfile
import warnings
from collections.abc import Callable, Sequence
from importlib.machinery import ModuleSpec
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from teleop_core.files import replace_durably

SUFFIX = importlib.machinery.EXTENSION_SUFFIXES[0]


def _name(key: str) -> str:
    return f"_haptic_study_loop_aot_{key}"


class _CacheFolderFinder(importlib.abc.MetaPathFinder):
    """Finds the kernel modules of a kernel cache folder by their names (`import_cached`),
    so that they are imported as any module is: once per process, and found by name
    where numba's on-disk cache looks a compiled function's module up."""

    def __init__(self) -> None:
        self.files: dict[str, Path] = {}

    def find_spec(
        self, fullname: str, path: Sequence[str] | None = None, target: ModuleType | None = None
    ) -> ModuleSpec | None:
        file = self.files.get(fullname)
        return None if file is None else importlib.util.spec_from_file_location(fullname, file)


_FINDER = _CacheFolderFinder()


def import_cached(name: str, file: Path) -> ModuleType:
    """The module `name` of the file `file` in a kernel cache folder (a C extension or
    Python source), imported through the import system; a name already imported in this
    process is that module (a kernel's name holds the digest of its source)."""
    if _FINDER not in sys.meta_path:
        sys.meta_path.append(_FINDER)
    _FINDER.files.setdefault(name, file)
    return importlib.import_module(name)


# `run_ticks`'s argument types (`tick.py`): (dtype, ndim) of a C-contiguous array, ndim 0
# a scalar, a tuple of them a tuple argument
_A1, _A2, _F, _I = ("float64", 1), ("float64", 2), ("float64", 0), ("int64", 0)
_S1, _S2 = ("float32", 1), ("float32", 2)
ESTIMATOR_ARGS = (_A2, _A1, _A1, _A1, _A2, _A1, _S2, _S2, _S1, _S1, _S1, _F, _A1, _A1, _A1)
"""`CausalEstimator.kernel_arrays`: buf, st, mean, std, mem, pv, w_ih_t, w_hh_t, b_ih,
b_hh, w_out (the GRU's weights in float32), b_out, target, ekf_s, ekf_v."""
LINK_ARGS = (_A2, _A1, _A1, _A2, _A1, _A1, _A1, _A1)
"""The in-kernel links (`link.kernel_links`): q_m, ls_m, lp_m, q_f, ls_f, lp_f, pool, pos."""
ARGS: tuple[Any, ...] = (
    *(_I, _A1, _A1, _A1, _A1, _A1, _A1, _F, _A1, _A1, _A2, _A2),
    ESTIMATOR_ARGS,
    *(_A1, _A2),
    LINK_ARGS,
)
_EST, _LINKS = 12, 15
_TUPLE_NAMES = {_EST: "estimator arrays (CausalEstimator.kernel_arrays)", _LINKS: "link arrays"}


def signature(nt: Any) -> Any:
    """`run_ticks`'s types (`ARGS`), in numba's terms (`nt`: `numba.types`)."""

    def of(spec: Any) -> Any:
        if isinstance(spec[0], tuple):
            return nt.Tuple(tuple(of(s) for s in spec))
        dtype, ndim = spec
        return getattr(nt, dtype) if ndim == 0 else nt.Array(getattr(nt, dtype), ndim, "C")

    return nt.int64(*(of(s) for s in ARGS))


def _fits(value: Any, spec: tuple[np.dtype[Any], int]) -> bool:
    """Whether `value` is what the compiled kernel reads for `spec`: its array with that
    dtype, ndim and C layout (the extension's wrapper does not check: another array is
    read as if it were one, out of its bounds), or a number."""
    dtype, ndim = spec
    if ndim == 0:
        return isinstance(value, int | float | np.integer | np.floating)
    return (
        isinstance(value, np.ndarray)
        and value.dtype == dtype
        and value.ndim == ndim
        and value.flags.c_contiguous
    )


def _dtypes(spec: Any) -> Any:
    """`spec` with numpy's dtypes for their names."""
    if isinstance(spec[0], tuple):
        return tuple(_dtypes(s) for s in spec)
    return np.dtype(spec[0]), spec[1]


_CHECK = _dtypes(ARGS)


def check_arguments(args: tuple[Any, ...], last: list[Any]) -> bool:
    """Whether the tuple arguments of `args` (the estimator's arrays, which come from a
    trained estimator's files, and the links') hold `ARGS`'s types: the extension's
    wrapper reads another tuple or array as if it were its signature's, out of its
    bounds. A tuple of another length, which no kernel takes, is a ValueError naming
    both lengths. `last` holds the tuples of the last call that fitted: the loop passes
    the same ones on every call, checked once. The other arguments are the loop's own
    arrays (`TeleopLoop`), not checked on every call."""
    if len(args) != len(_CHECK):
        return False
    if last and args[_EST] is last[0] and args[_LINKS] is last[1]:
        return True
    for i in _TUPLE_NAMES:
        value, spec = args[i], _CHECK[i]
        if not isinstance(value, tuple):
            return False
        if len(value) != len(spec):
            raise ValueError(
                f"the loop kernel's {_TUPLE_NAMES[i]}: expected {len(spec)}, got {len(value)}"
            )
        if not all(_fits(v, s) for v, s in zip(value, spec, strict=True)):
            return False
    last[:] = [args[i] for i in _TUPLE_NAMES]
    return True


def load_ahead_of_time(
    folder: Path, key: str, jit: Callable[[], Callable[..., int]]
) -> Callable[..., int] | None:
    """The compiled kernel of `key` from `folder`, if it was built (else None); `jit`
    gives the JIT kernel for a call whose argument types it refuses."""
    if not is_built(folder, key):
        return None
    module = import_cached(_name(key), folder / f"{_name(key)}{SUFFIX}")
    return _with_fallback(module.run_ticks, jit)


def is_built(folder: Path, key: str) -> bool:
    """Whether the kernel of `key` was compiled into `folder`."""
    return (folder / f"{_name(key)}{SUFFIX}").is_file()


def can_build(folder: Path, key: str) -> bool:
    """Whether `build_ahead_of_time` will try (it failed before: it does not)."""
    return not (folder / f"{_name(key)}.failed").exists()


def build_ahead_of_time(
    folder: Path, key: str, py_func: Callable[..., int], jit: Callable[..., int]
) -> Callable[..., int] | None:
    """Compile `py_func` (the kernel's Python source) into `folder` and load it; None
    (and a marker, so no later process tries again) where that fails."""
    if not can_build(folder, key):
        return None
    try:
        from numba import types as nt

        with warnings.catch_warnings():  # its pending deprecation, not the user's concern
            warnings.simplefilter("ignore")
            from numba.pycc import CC

        with tempfile.TemporaryDirectory(dir=folder, prefix=".aot.") as tmp:
            cc = CC(_name(key))
            cc.output_dir = tmp
            cc.target_cpu = "host"
            cc.verbose = False
            cc.export("run_ticks", signature(nt))(py_func)
            cc.compile()
            # tmp is inside folder: one atomic rename, never a half-written extension
            replace_durably(Path(tmp) / f"{_name(key)}{SUFFIX}", folder / f"{_name(key)}{SUFFIX}")
    except Exception as exc:  # any failure: the JIT kernel runs instead
        try:
            (folder / f"{_name(key)}.failed").write_text(f"{type(exc).__name__}: {exc}\n")
        except OSError:
            pass
        return None
    return load_ahead_of_time(folder, key, lambda: jit)


def _with_fallback(
    ahead: Callable[..., int], jit: Callable[[], Callable[..., int]]
) -> Callable[..., int]:
    """`ahead`, or from the first call whose argument types it refuses, `jit()`; the
    types are checked here first (`check_arguments`), since the extension reads an
    array of another dtype or shape without a word."""
    current: list[Callable[..., int]] = [ahead]
    last: list[Any] = []

    def run_ticks(*args: Any) -> int:
        if current[0] is ahead and not check_arguments(args, last):
            current[0] = jit()
        try:
            return current[0](*args)
        except TypeError:
            if current[0] is not ahead:
                raise
            current[0] = jit()
            return current[0](*args)

    run_ticks.ahead_of_time = True  # type: ignore[attr-defined]
    return run_ticks
