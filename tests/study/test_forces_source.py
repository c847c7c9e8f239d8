"""Where a trial's forces came from (`study_rows.forces_source`) and the sentence of
methods.md that says so."""

from __future__ import annotations

import json

import pytest

from study.analysis.methods import _forces_sentence
from study.analysis.source import DataSource
from study.analysis.stats import Analysis
from study.protocol.study_rows import forces_source


@pytest.mark.parametrize(
    ("driver", "summary", "expected"),
    [
        ("hardware", json.dumps({"forces": "measured", "phantom": "physical"}), "measured"),
        ("hardware", {"forces": "measured"}, "measured"),  # PostgreSQL decodes the JSON
        ("hardware", json.dumps({"dial_firmware": "1.0.0"}), "simulated"),  # the dial alone
        ("keyboard", None, "simulated"),
        ("simulated", json.dumps({"forces": "simulated"}), "simulated"),
        ("hardware", "{not json", "simulated"),
        ("hardware", json.dumps(["forces", "measured"]), "simulated"),
        ("imported", None, "unknown"),
    ],
)
def test_forces_source(driver: str, summary: object, expected: str) -> None:
    assert forces_source(driver, summary) == expected


def _analysis(drivers: list[str], forces: dict[str, int]) -> Analysis:
    return Analysis([], [], [], [], source=DataSource.of_drivers(drivers), forces_by_source=forces)


def test_methods_say_which_forces_were_measured() -> None:
    (line,) = _forces_sentence(_analysis(["hardware"] * 4, {"measured": 4}))
    assert line.startswith("The forces of 4 of them were measured, with the real drive")
    assert "simulated" not in line
    (line,) = _forces_sentence(
        _analysis(["hardware"] * 3 + ["simulated"], {"measured": 2, "simulated": 2})
    )
    assert "The forces of 2 of them were measured" in line
    assert line.endswith("; those of 2 came from the simulated follower and phantom.")
    # people on the dial alone or the keyboard: their actions measured, the forces not
    (line,) = _forces_sentence(_analysis(["keyboard", "hardware"], {"simulated": 2}))
    assert line == (
        "The forces of the 2 trials people drove came from the simulated follower and "
        "phantom (no drive unit in the loop)."
    )
    # a simulated study says so in its note already; imported trials: nothing known
    assert _forces_sentence(_analysis(["simulated"] * 3, {"simulated": 3})) == []
    assert _forces_sentence(_analysis(["imported"] * 3, {"unknown": 3})) == []
    assert _forces_sentence(_analysis([], {})) == []
