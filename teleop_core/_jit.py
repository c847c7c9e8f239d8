"""numba's `njit`, with numba imported only when compiled code is first needed.

Importing numba and setting up its CPU target costs about 1.5 s per process, even when
every function comes from its on-disk cache. A simulated trial whose loop kernel is
compiled ahead of time (`teleop_core.loop.aot`) needs none of it, yet imports every
module that defines a kernel function. So those modules decorate with this `njit`: it
keeps the Python function and makes numba's dispatcher (with the same options) on the
first call, or when numba compiles another function that calls it (a numba typeof
hook, registered when numba is first imported here, types it as that dispatcher).

numba has no lazy mode of its own (its `cache=True` still imports numba and builds the
target context on load), hence this small wrapper.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable
from typing import Any

_HOOKED = False


def numba_module() -> Any:
    """numba, with the typeof hook that lets compiled code call a `LazyJit`: what code
    that compiles with numba directly imports it through."""
    global _HOOKED
    # lazy: numba costs 0.3 s at start-up
    import numba

    if not _HOOKED:
        from numba.core import types
        from numba.extending import typeof_impl

        @typeof_impl.register(LazyJit)
        def _typeof_lazy(val: LazyJit, c: object) -> types.Dispatcher:
            return types.Dispatcher(val.dispatcher)

        _HOOKED = True
    return numba


def _resolve(module: str, qualname: str) -> Any:
    """The module-level object `module.qualname` (how a `LazyJit` is pickled)."""
    obj: Any = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


class LazyJit:
    """A function compiled by numba's `njit(**options)` when first needed."""

    def __init__(self, py_func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = py_func
        self._options = options
        self._dispatcher: Any = None
        functools.update_wrapper(self, py_func)

    @property
    def dispatcher(self) -> Any:
        """numba's dispatcher (imports numba on first use)."""
        if self._dispatcher is None:
            self._dispatcher = numba_module().njit(**self._options)(self.py_func)
        return self._dispatcher

    def __call__(self, *args: Any) -> Any:
        return self.dispatcher(*args)

    def __getattr__(self, name: str) -> Any:
        # what a dispatcher has and a function not (stats, signatures, ...)
        if name.startswith("__") or name in ("_dispatcher", "_options", "py_func"):
            raise AttributeError(name)
        return getattr(self.dispatcher, name)

    def __reduce__(self) -> tuple[Callable[..., Any], tuple[str, str]]:
        return _resolve, (self.py_func.__module__, self.py_func.__qualname__)


def njit(*args: Any, **options: Any) -> Any:
    """`numba.njit`, as `@njit`, `@njit(cache=True, ...)`; numba imported when needed."""
    if args and callable(args[0]) and not options:
        return LazyJit(args[0], {})
    return lambda py_func: LazyJit(py_func, options)
