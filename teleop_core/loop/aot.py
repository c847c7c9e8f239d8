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

numba.pycc is numba's own ahead-of-time compiler (deprecated in favour of a successor
that is not released yet); nothing else compiles a numba kernel ahead of time.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from teleop_core.files import replace_durably

SUFFIX = importlib.machinery.EXTENSION_SUFFIXES[0]


def _name(key: str) -> str:
    return f"_haptic_study_loop_aot_{key}"


def signature(nt: Any) -> Any:
    """`run_ticks`'s types (`tick.py`), in numba's terms (`nt`: `numba.types`)."""
    a1, a2, f = nt.float64[::1], nt.float64[:, ::1], nt.float64
    s1, s2 = nt.float32[::1], nt.float32[:, ::1]
    # CausalEstimator.kernel_arrays: buf, st, mean, std, mem, pv, w_ih_t, w_hh_t, b_ih, b_hh,
    # w_out (the GRU's weights in float32), b_out, target, ekf_s, ekf_v
    est = nt.Tuple((a2, a1, a1, a1, a2, a1, s2, s2, s1, s1, s1, f, a1, a1, a1))
    # the in-kernel links: q_m, ls_m, lp_m, q_f, ls_f, lp_f, pool, pos
    links = nt.Tuple((a2, a1, a1, a2, a1, a1, a1, a1))
    return nt.int64(nt.int64, a1, a1, a1, a1, a1, a1, f, a1, a1, a2, a2, est, a1, a2, links)


def load_ahead_of_time(
    folder: Path, key: str, jit: Callable[[], Callable[..., int]]
) -> Callable[..., int] | None:
    """The compiled kernel of `key` from `folder`, if it was built (else None); `jit`
    gives the JIT kernel for a call whose argument types it refuses."""
    if not is_built(folder, key):
        return None
    path, name = folder / f"{_name(key)}{SUFFIX}", _name(key)
    module = sys.modules.get(name)
    if module is None:
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:  # pragma: no cover - a file path has one
            return None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[name] = module
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
    """`ahead`, or from the first call whose argument types it refuses, `jit()`."""
    current: list[Callable[..., int]] = [ahead]

    def run_ticks(*args: Any) -> int:
        try:
            return current[0](*args)
        except TypeError:
            if current[0] is not ahead:
                raise
            current[0] = jit()
            return current[0](*args)

    run_ticks.ahead_of_time = True  # type: ignore[attr-defined]
    return run_ticks
