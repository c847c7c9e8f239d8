"""The loop's compiled 1 kHz tick (`tick.py`) with an environment bound in: `kernel_for`.

The environment is any numba function `env(state, params, insertion_m, speed_m_s,
rotation_rad, dt_s, out)` that writes ENV_OUT values to `out`. `kernel_for(env)`
compiles the tick with the environment bound in, so a phantom plugs in without touching
this kernel; passing the function as an argument instead costs ~20 us of numba type
dispatch per call. Compiling takes 3.5-5 s, so a module-level environment's kernel is
kept on disk: compiled ahead of time into an extension module (`aot.py`), which a later
process imports without numba, or, where that cannot be built, through numba's on-disk
cache. Either way a second process compiles nothing (`kernel_for`).
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.metadata
import importlib.util
import inspect
import os
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

from teleop_core.files import write_atomically
from teleop_core.loop.aot import (
    build_ahead_of_time,
    can_build,
    import_cached,
    is_built,
    load_ahead_of_time,
)
from teleop_core.loop.tick import _make

_KERNELS: dict[object, Callable[..., int]] = {}


def kernel_for(
    env_fn: Callable[..., None], notice: Callable[[str], None] | None = None
) -> Callable[..., int]:
    """The compiled tick with `env_fn` bound in (compiled on first use, then reused).

    An environment importable by name (a module-level numba function) gets the tick from
    the kernel cache folder: the extension compiled ahead of time (`aot.py`), or numba's
    on-disk cache of the kernel's source written once into a module of its own that
    imports the environment as a global (numba caches a module-level function, not a
    closure). Anything else, or an unwritable cache folder, is compiled in the process.
    `notice` (for example the `study` command's, on stderr) is told when the kernel is
    compiled for the first time on this machine rather than loaded from the cache folder.
    """
    if env_fn not in _KERNELS:
        _KERNELS[env_fn] = _cached_kernel(env_fn, notice) or _make(env_fn)
    return _KERNELS[env_fn]


def _cache_key(env_fn: Callable[..., None]) -> str | None:
    """The key of `env_fn`'s kernel in the cache folder (None for an environment not
    importable by name, whose kernel every process compiles)."""
    try:
        found = _kernel_module(env_fn)
    except (OSError, ImportError, AttributeError, SyntaxError):
        return None
    return None if found is None else found[2]


def is_compiled(env_fn: Callable[..., None]) -> bool:
    """Whether `env_fn`'s kernel is already compiled ahead of time in the kernel cache
    folder, so that a process only loads it."""
    key = _cache_key(env_fn)
    return key is not None and is_built(_cache_dir(), key)


def needs_compiling(env_fn: Callable[..., None]) -> bool:
    """Whether the next process to run `env_fn` would compile its kernel ahead of time:
    importable by name, not built yet, and no earlier attempt failed on this machine
    (without a C compiler the JIT kernel from numba's cache runs instead, every time)."""
    key = _cache_key(env_fn)
    return key is not None and not is_built(_cache_dir(), key) and can_build(_cache_dir(), key)


def _cache_dir() -> Path:
    root = os.environ.get("HAPTIC_STUDY_CACHE") or os.environ.get("XDG_CACHE_HOME")
    base = Path(root) if root else Path.home() / ".cache"
    return (base if os.environ.get("HAPTIC_STUDY_CACHE") else base / "haptic-study") / "kernels"


def _source_digest() -> str:
    """Digest of every teleop_core source file and numba's version: numba's cache does not
    see a change in a function the kernel calls from another file, so the kernel's module
    name changes with the sources instead."""
    digest = hashlib.sha256(importlib.metadata.version("numba").encode())
    package = Path(__file__).resolve().parents[1]
    for path in sorted(package.rglob("*.py")):
        digest.update(path.relative_to(package).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _kernel_source(module: str, name: str) -> str:
    lines = inspect.getsource(_make).splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip() == "@numba.njit")
    end = max(i for i, line in enumerate(lines) if line.strip() == "return run_ticks")
    body = textwrap.dedent("\n".join(lines[start:end]))
    body = body.replace("@numba.njit", "@numba.njit(cache=True)", 1)
    return (
        f'"""The loop kernel for {module}.{name}, written by teleop_core.loop.kernel so that\n'
        'numba can cache it on disk (see kernel_for)."""\n\n'
        "import numpy as np\n\n"
        "from teleop_core._jit import numba_module\n\n"
        "numba = numba_module()\n\n"
        "import teleop_core.loop.tick as _tick\n\n"
        "globals().update({k: v for k, v in vars(_tick).items() if not k.startswith('__')})\n"
        f"from {module} import {name} as env_fn  # noqa: E402\n\n\n"
        f"{body}\n"
    )


def _kernel_module(env_fn: Callable[..., None]) -> tuple[str, str, str] | None:
    """The environment's module and name, and the key of its kernel's source (None for
    an environment not importable by name)."""
    py_func = getattr(env_fn, "py_func", None)
    module, name = getattr(env_fn, "__module__", None), getattr(py_func, "__qualname__", "")
    if py_func is None or not module or module == "__main__" or not name.isidentifier():
        return None
    if getattr(importlib.import_module(module), name, None) is not env_fn:
        return None
    global _DIGEST
    _DIGEST = _DIGEST or _source_digest()
    source = _kernel_source(module, name)
    return module, name, hashlib.sha256(f"{_DIGEST}{source}".encode()).hexdigest()[:16]


def _cached_kernel(
    env_fn: Callable[..., None], notice: Callable[[str], None] | None = None
) -> Callable[..., int] | None:
    """The kernel compiled ahead of time (`aot.py`), else through numba's on-disk cache;
    None where neither can be kept (an environment not importable by name, an
    unwritable cache folder); `notice` is told before a first compilation."""
    try:
        found = _kernel_module(env_fn)
        if found is None:
            return None
        module, name, key = found
        folder = _cache_dir()
        ahead = load_ahead_of_time(folder, key, lambda: _jit_kernel(folder, module, name, key)[0])
        if ahead is not None:
            return ahead
        jit, first = _jit_kernel(folder, module, name, key)
    except (OSError, ImportError, AttributeError, SyntaxError):
        return None
    if (first or can_build(folder, key)) and notice is not None:
        notice(f"compiling the simulation loop for {name} (once; later runs load it)")
    return build_ahead_of_time(folder, key, jit.py_func, jit) or jit


def _jit_kernel(folder: Path, module: str, name: str, key: str) -> tuple[Any, bool]:
    """The kernel through numba's on-disk cache (numba's dispatcher): its source written
    once into a module of its own that imports the environment as a global (numba caches
    a module-level function, not a closure); and whether the source was written just now."""
    path = folder / f"loop_kernel_{key}.py"
    first = not path.is_file()
    if first:
        folder.mkdir(parents=True, exist_ok=True)
        write_atomically(path, _kernel_source(module, name))
    generated = import_cached(f"_haptic_study_{path.stem}", path)
    return generated.run_ticks, first


_DIGEST = ""
