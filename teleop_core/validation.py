"""Range checks of parameter fields, each failure one line naming the field, its value
and what was expected (the frozen parameter classes call them in `__post_init__`).

Two functions rather than a validation library: pydantic or msgspec would validate
types the dataclasses already declare, cost their import at start-up (the `study`
command and the control loop load these classes), and phrase the errors their own way.
"""

from __future__ import annotations

import math
from numbers import Real

from teleop_core.errors import TeleopInputError

__all__ = ["require_nonnegative", "require_positive"]


def _finite_number(value: object) -> bool:
    """A finite real number (Python's or numpy's)."""
    return isinstance(value, Real) and math.isfinite(value)


def require_positive(obj: object, *names: str, error: type[ValueError] = TeleopInputError) -> None:
    """Raise `error` unless each field `names` of `obj` is a finite number > 0."""
    for name in names:
        value = getattr(obj, name)
        if not (_finite_number(value) and value > 0):
            raise error(f"{type(obj).__name__}.{name} = {value!r}; expected a finite value > 0")


def require_nonnegative(
    obj: object, *names: str, error: type[ValueError] = TeleopInputError
) -> None:
    """Raise `error` unless each field `names` of `obj` is a finite number >= 0."""
    for name in names:
        value = getattr(obj, name)
        if not (_finite_number(value) and value >= 0):
            raise error(f"{type(obj).__name__}.{name} = {value!r}; expected a finite value >= 0")
