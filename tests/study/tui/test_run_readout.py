"""What the run screen's readout says of a trial: no torque on the hand in VO (nothing
is rendered there), the rendered torque in HV."""

from __future__ import annotations

import numpy as np

from study.protocol.tasks import get_task
from study.tui.run_live import task_lines
from study.tui.trial_runner import LiveState


def _frame(task_name: str, condition: str, **values: float):
    task = get_task(task_name)
    row = np.zeros((1, len(task.sample_columns)))
    index = task.column_index()
    for name, value in values.items():
        row[0, index[name]] = value
    live = LiveState()
    live.start(task, condition)
    live.push(row)
    return live.frame()


def test_vo_shows_no_torque_on_the_hand_and_hv_shows_it() -> None:
    vo = task_lines(_frame("lcca", "VO", t_s=0.01, dial_torque_n_m=-0.0132))
    hv = task_lines(_frame("lcca", "HV", t_s=0.01, dial_torque_n_m=-0.0132))
    assert vo[-1] == "torque on the hand: none (VO, no haptic feedback)"
    assert hv[-1] == "torque on the hand -13.2 mN m"  # -0.0132 N m in mN m


def test_notes_vo_shows_no_rendered_torque() -> None:
    vo = task_lines(_frame("notes", "VO", t_s=0.01, torque_rendered_n_m=0.004))
    hv = task_lines(_frame("notes", "HV", t_s=0.01, torque_rendered_n_m=0.004))
    assert vo[-1] == "torque rendered: none (VO, no haptic feedback)"
    assert hv[-1] == "torque rendered   +4.0 mN m"
