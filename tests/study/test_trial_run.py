"""`run_trial`, the one trial loop: what it steps, what it tells a caller per step, and
the `Task` it runs (an ABC of three hooks)."""

from __future__ import annotations

import numpy as np
import pytest

from study.protocol.tasks import Task, get_task
from study.protocol.traits import simulated_participant
from study.protocol.trial_run import TrialSteps, rendered_gain, run_trial, simulate_trial


class Recorder(TrialSteps):
    def __init__(self) -> None:
        self.events: list[str] = []
        self.rows: list[np.ndarray] = []

    def started(self, loop) -> None:  # type: ignore[no-untyped-def]
        self.events.append(f"started at {loop.t_s:g}")

    def before_step(self, loop) -> None:  # type: ignore[no-untyped-def]
        self.events.append("before")

    def after_step(self, loop, samples) -> None:  # type: ignore[no-untyped-def]
        self.events.append("after")
        self.rows.append(samples)

    def finished(self, loop) -> None:  # type: ignore[no-untyped-def]
        self.events.append("finished")


def test_a_task_without_its_three_hooks_cannot_be_made() -> None:
    class Half(Task):
        declaration = get_task("notes").declaration

        def make_loop(self, condition, seed, **kwargs):  # type: ignore[no-untyped-def, override]
            raise AssertionError

    with pytest.raises(TypeError, match=r"simulated_driver.*trial_measures"):
        Half()  # type: ignore[abstract]


@pytest.mark.parametrize("step_s", [1.0, 0.5])
def test_the_trial_is_stepped_to_its_limit_and_each_step_is_told(step_s: float) -> None:
    task = get_task("notes")
    person = simulated_participant("novice", 2)
    # the reference: the same loop and driver advanced by hand in one call
    loop = task.make_loop("HV", 5)
    loop.start(task.simulated_driver(person, 3.0, None))
    by_hand = loop.advance(3.0)
    steps = Recorder()
    run = run_trial(
        task, "HV", 5, task.simulated_driver(person, 3.0, None), 3.0, step_s=step_s, steps=steps
    )
    n = round(3.0 / step_s)  # 3 s, not reached the target: every step to the limit
    assert steps.events == ["started at 0", *["before", "after"] * n, "finished"]
    np.testing.assert_array_equal(np.concatenate(steps.rows), by_hand)
    np.testing.assert_array_equal(run.samples, by_hand)
    assert run.completion_time_s == pytest.approx(by_hand[-1, 0])
    assert run.success is False
    assert run.rendered_gain == {}  # NOTES has no dial
    assert run.measures == task.trial_measures(by_hand, False)[0]


def test_vo_renders_no_gain_and_hv_the_tasks_default() -> None:
    lcca = get_task("lcca")
    assert rendered_gain(lcca, "VO", None) == {"haptic_gain_n_m_per_n": 0.0}
    assert rendered_gain(lcca, "HV", None) == {"haptic_gain_n_m_per_n": 0.02}
    assert rendered_gain(lcca, "HV", 0.01) == {"haptic_gain_n_m_per_n": 0.01}


def test_a_simulated_trial_stops_at_its_limit() -> None:
    result = simulate_trial(get_task("notes"), simulated_participant("expert", 1), "VO", 3, 2.0)
    # 100 samples a second for 2 s (teleop_core.notes.task's acquisition rate)
    assert len(result.frame) == 200
    assert result.summary["completion_time_s"] == pytest.approx(2.0)
    assert result.summary["success"] is False
