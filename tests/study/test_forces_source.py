"""Where a trial's forces came from (`study_rows.forces_source`) and the sentence of
methods.md that says so."""

from __future__ import annotations

import json

import pytest

from study.analysis.methods import _end_sentence, _forces_sentence
from study.analysis.source import DataSource
from study.analysis.stats import Analysis
from study.protocol.study_rows import forces_source, trial_end


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


@pytest.mark.parametrize(
    ("summary", "expected"),
    [
        (json.dumps({"forces": "measured", "end": "button"}), "button"),
        ({"end": "experimenter"}, "experimenter"),  # PostgreSQL decodes the JSON
        (json.dumps({"end": "time_limit"}), "time_limit"),
        (json.dumps({"forces": "simulated"}), None),  # a simulated phantom decides itself
        (json.dumps({"end": "someone"}), None),  # not one of the ends
        ("{not json", None),
        (None, None),
    ],
)
def test_trial_end(summary: object, expected: str | None) -> None:
    assert trial_end(summary) == expected


def _ended(ends: dict[str, int]) -> Analysis:
    return Analysis([], [], [], [], source=DataSource.of_drivers(["hardware"]), ends=ends)


def test_methods_say_who_ended_the_physical_phantom_s_trials() -> None:
    (line,) = _end_sentence(_ended({"button": 5, "experimenter": 2, "time_limit": 1}))
    assert line == (
        "On the physical phantom a person judged when the tip reached the target, which "
        "ended the trial as a success: 5 by the participant's button and 2 by the "
        "experimenter; 1 reached the time limit and count as failures."
    )
    (line,) = _end_sentence(_ended({"time_limit": 3}))
    assert line.endswith("a success: in no trial; 3 reached the time limit and count as failures.")
    (line,) = _end_sentence(_ended({"button": 1}))
    assert line.endswith("a success: 1 by the participant's button.")
    assert _end_sentence(_ended({})) == []  # no physical phantom: nothing to say
