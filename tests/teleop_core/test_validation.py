"""One validation module for the parameter classes (`teleop_core.validation`): the same
one-line error from the follower's, the master's and the NOTES device's parameters."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from teleop_core.errors import TeleopInputError
from teleop_core.follower.params import FollowerPlantParams
from teleop_core.notes.params import NotesParamsError, TranslationParams
from teleop_core.validation import require_nonnegative, require_positive


class _Box:
    def __init__(self, **values: object) -> None:
        self.__dict__.update(values)


def test_a_value_out_of_range_is_one_line_naming_the_field_and_the_range() -> None:
    with pytest.raises(TeleopInputError) as info:
        require_positive(_Box(mass_kg=0.0), "mass_kg")
    assert str(info.value) == "_Box.mass_kg = 0.0; expected a finite value > 0"
    with pytest.raises(TeleopInputError, match=r"^_Box.b = -1; expected a finite value >= 0$"):
        require_nonnegative(_Box(b=-1), "b")
    for bad in (math.nan, math.inf, "1"):
        with pytest.raises(TeleopInputError):
            require_positive(_Box(x=bad), "x")


def test_numpy_numbers_and_zero_where_allowed_pass() -> None:
    require_positive(_Box(x=np.float32(0.5), n=np.int64(3)), "x", "n")
    require_nonnegative(_Box(x=0.0), "x")


def test_the_parameter_classes_use_it_with_their_own_error() -> None:
    with pytest.raises(TeleopInputError, match=r"^FollowerPlantParams\.\w+ = -1\.0; expected a"):
        replace(FollowerPlantParams(), inertia_kg_m2=-1.0)
    with pytest.raises(NotesParamsError, match=r"^TranslationParams\.\w+ = 0\.0; expected a"):
        replace(TranslationParams(), **{TranslationParams._limit: 0.0})
