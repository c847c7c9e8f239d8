"""The worked example `examples/probe_task` in the fast lane: imported from its own folder
(the slow lane installs it through its entry point and runs a whole study on it,
`tests/study/tui/test_adding_a_task.py`), its task registers under the name its
pyproject's entry point gives, and one trial of its loop driven by its simulated
participant gives the closed forms its docstring states, computed here by hand."""

from __future__ import annotations

import importlib
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from study.protocol.tasks import get_task, register, unregister

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "probe_task"
SPEED_M_S = 0.05 * 0.8
"""k_v * aim: the rate gain (0.05 m/s per rad) times the simulated participant's aim."""


@pytest.fixture
def example(monkeypatch: pytest.MonkeyPatch) -> Iterator[ModuleType]:
    """The example's task module, imported from the checkout; unregistered and unloaded
    afterwards so that no other test finds it."""
    monkeypatch.syspath_prepend(str(EXAMPLE))
    try:
        yield importlib.import_module("haptic_study_probe.task")
    finally:
        unregister("probe")
        for name in [m for m in sys.modules if m.startswith("haptic_study_probe")]:
            del sys.modules[name]


def test_the_example_registers_under_its_entry_points_name(example: ModuleType) -> None:
    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text(encoding="utf-8"))
    entry = project["project"]["entry-points"]["haptic_study.tasks"]
    assert entry == {"probe": "haptic_study_probe.task:TASK"}
    assert register(example.TASK) is example.TASK
    assert get_task("probe") is example.TASK


def test_one_trial_gives_the_closed_forms(example: ModuleType) -> None:
    task = example.TASK
    loop = task.make_loop("HV", 0)
    loop.start(task.simulated_driver(None, 10.0, None))
    samples = loop.advance(10.0)
    # depth / speed = 0.08 m / 0.04 m/s = 2 s, at 100 samples a second
    assert samples.shape == (200, len(task.sample_columns))
    assert samples[-1, 0] == pytest.approx(2.0)
    assert loop.success
    column = task.column_index()
    assert samples[:, column["medium_speed_m_s"]] == pytest.approx(SPEED_M_S)
    assert samples[-1, column["depth_m"]] == pytest.approx(0.08)
    measures, _ = task.trial_measures(samples, True)
    # F = B v = 40 N s/m * 0.04 m/s
    assert measures == {"peak_push_force_n": pytest.approx(1.6)}
