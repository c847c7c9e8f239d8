"""The loop's compiled 1 kHz tick (`tick.py`) with an environment bound in: `kernel_for`.

The environment is any numba function `env(state, params, insertion_m, speed_m_s,
rotation_rad, dt_s, out)` that writes ENV_OUT values to `out`. `kernel_for(env)`
compiles the tick with the environment bound in, so a phantom plugs in without touching
this kernel; passing the function as an argument instead costs ~20 us of numba type
dispatch per call. Compiling takes 3.5-5 s, so a module-level environment's kernel goes
through numba's on-disk cache: a second process compiles nothing (`kernel_for`).
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import os
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba

from teleop_core.loop import layout
from teleop_core.loop.tick import _make

_KERNELS: dict[object, Callable[..., None]] = {}

COMPILE_NOTICE: Callable[[str], None] | None = None
"""Told (for example by the `study` command, on stderr) when a kernel is compiled for the
first time on this machine rather than loaded from the on-disk cache."""


def kernel_for(env_fn: Callable[..., None]) -> Callable[..., None]:
    """The compiled tick with `env_fn` bound in (compiled on first use, then reused).

    An environment importable by name (a module-level numba function) gets the tick from
    numba's on-disk cache: the kernel's source is written once into a module of its own
    that imports the environment as a global, which numba caches like any module-level
    function (a closure it cannot cache). Anything else, or an unwritable cache folder,
    is compiled in the process as before.
    """
    if env_fn not in _KERNELS:
        _KERNELS[env_fn] = _cached_kernel(env_fn) or _make(env_fn)
    return _KERNELS[env_fn]


def _cache_dir() -> Path:
    root = os.environ.get("HAPTIC_STUDY_CACHE") or os.environ.get("XDG_CACHE_HOME")
    base = Path(root) if root else Path.home() / ".cache"
    return (base if os.environ.get("HAPTIC_STUDY_CACHE") else base / "haptic-study") / "kernels"


def _source_digest() -> str:
    """Digest of every teleop_core source file and numba's version: numba's cache does not
    see a change in a function the kernel calls from another file, so the kernel's module
    name changes with the sources instead."""
    digest = hashlib.sha256(numba.__version__.encode())
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
        "import numba\n"
        "import numpy as np\n\n"
        "import teleop_core.loop.tick as _tick\n\n"
        "globals().update({k: v for k, v in vars(_tick).items() if not k.startswith('__')})\n"
        f"from {module} import {name} as env_fn  # noqa: E402\n\n\n"
        f"{body}\n"
    )


def _cached_kernel(env_fn: Callable[..., None]) -> Callable[..., None] | None:
    py_func = getattr(env_fn, "py_func", None)
    module, name = getattr(env_fn, "__module__", None), getattr(py_func, "__qualname__", "")
    if py_func is None or not module or module == "__main__" or not name.isidentifier():
        return None
    try:
        if getattr(importlib.import_module(module), name) is not env_fn:
            return None
        global _DIGEST
        _DIGEST = _DIGEST or _source_digest()
        source = _kernel_source(module, name)
        key = hashlib.sha256(f"{_DIGEST}{source}".encode()).hexdigest()[:16]
        folder = _cache_dir()
        path = folder / f"loop_kernel_{key}.py"
        first = not path.is_file()
        if first:
            folder.mkdir(parents=True, exist_ok=True)
            tmp = folder / f".{path.name}.{os.getpid()}"
            tmp.write_text(source)
            os.replace(tmp, path)
        spec = importlib.util.spec_from_file_location(f"_haptic_study_{path.stem}", path)
        if spec is None or spec.loader is None:  # pragma: no cover - a file path always has one
            return None
        generated = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = generated  # numba's cache finds the module by name
        spec.loader.exec_module(generated)
    except (OSError, ImportError, AttributeError, SyntaxError):
        return None
    if first and COMPILE_NOTICE is not None:
        COMPILE_NOTICE(f"compiling the simulation loop for {name} (once; later runs load it)")
    kernel: Callable[..., None] = generated.run_ticks
    return kernel


_DIGEST = ""


def __getattr__(name: str) -> Any:
    """The environment's outputs (`E_*`, `ENV_OUT`) are defined in `layout.py`; an
    environment may still import them from here, where they were first."""
    if name == "ENV_OUT" or name.startswith("E_"):
        return getattr(layout, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
