"""What the run screen's readout says of a trial: no torque on the hand in VO (nothing
is rendered there), the rendered torque in HV."""

from __future__ import annotations

import numpy as np
import pytest

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


BLOCK_DESIGN = """\
name = "block summary"
seed = 5
trials_per_condition = 3
practice_trials = 1
[groups]
novice = 1
"""


def _store(session, p, block, index, *, practice=False, status="completed", attempt=1, t_s, peak):
    from db.models.trial import Trial

    trial = Trial(
        participant_id=p.id,
        block_id=block.id,
        task="lcca",
        condition=block.condition,
        block_index=block.block_index,
        trial_index=index,
        attempt=attempt,
        practice=practice,
        status=status,
        completion_time_s=t_s,
        success=t_s < 30,
        driver="simulated",
        measure_values={
            "peak_proximal_force_n": peak,
            "peak_distal_force_n": peak / 4,
            "wall_contacts": 2 * index,
        },
    )
    session.add(trial)
    session.flush()
    return trial.id


def test_the_block_summary_is_the_mean_and_sd_of_its_measured_trials(tmp_path) -> None:
    from sqlalchemy.orm import Session

    from db.migrate import open_database
    from db.models.study import Participant
    from study.protocol.design import parse_design
    from study.protocol.roster import add_participant, create_study
    from study.tui.trial_summary import BlockStat, report_lines, trial_report

    engine = open_database(str(tmp_path / "s.db"), create=True)
    create_study(engine, parse_design(BLOCK_DESIGN), BLOCK_DESIGN)
    add_participant(engine, "novice")
    with Session(engine) as session, session.begin():
        p = session.query(Participant).one()
        block = p.blocks[0]
        # a practice trial and an interrupted attempt: neither counts
        _store(session, p, block, 0, practice=True, t_s=99.0, peak=9.0)
        _store(session, p, block, 0, status="interrupted", t_s=77.0, peak=7.0)
        first = _store(session, p, block, 0, attempt=2, t_s=20.0, peak=1.0)
        _store(session, p, block, 1, t_s=24.0, peak=1.5)
        last = _store(session, p, block, 2, t_s=31.0, peak=2.0)
    mid_block = trial_report(engine, first)
    report = trial_report(engine, last)
    engine.dispose()
    assert mid_block.block is None
    assert mid_block.success is True
    assert mid_block.measures == [
        ("completion time", "s", 20.0),
        ("peak proximal force", "N", 1.0),
        ("peak distal force", "N", 0.25),
        ("wall contacts", "", 0),
    ]
    # by hand: times 20, 24, 31: mean 25, SD sqrt((25 + 1 + 36) / 2) = sqrt(31);
    # peaks 1, 1.5, 2: mean 1.5, SD 0.5; contacts 0, 2, 4: mean 2, SD 2
    assert report.block == [
        BlockStat("completion time", "s", 3, 25.0, pytest.approx(31**0.5)),
        BlockStat("peak proximal force", "N", 3, 1.5, pytest.approx(0.5)),
        BlockStat("peak distal force", "N", 3, 0.375, pytest.approx(0.125)),
        BlockStat("wall contacts", "", 3, 2.0, pytest.approx(2.0)),
    ]
    lines = report_lines("P001", report)
    condition = report.condition
    assert lines[:3] == [
        f"P001: lcca/{condition} trial 3 stored",
        "  success no",
        "  completion time 31.0 s",
    ]
    assert "  completion time 25.0 ± 5.57 s" in lines
    assert "  peak proximal force 1.50 ± 0.50 N" in lines
    assert "  wall contacts 4" in lines  # the trial's count, a whole number
    assert "  wall contacts 2.00 ± 2.00" in lines  # the block's mean and SD
    assert all(len(line) <= 38 for line in lines)  # the readout's width
    # in 12 rows both fit; in 8 the block's summary whole, the trial's own figures left
    # out; in 6 the summary cut, the line saying how many measures are not shown
    assert report_lines("P001", report, rows=12) == lines
    assert report_lines("P001", report, rows=8) == [
        f"P001: lcca/{condition} trial 3 stored",
        "  success no (its figures: v)",
        f"block lcca/{condition} done:",
        "  3 measured trials, mean ± SD",
        "  completion time 25.0 ± 5.57 s",
        "  peak proximal force 1.50 ± 0.50 N",
        "  peak distal force 0.38 ± 0.12 N",
        "  wall contacts 2.00 ± 2.00",
    ]
    assert report_lines("P001", report, rows=6)[4:] == [
        "  completion time 25.0 ± 5.57 s",
        "  3 more measures: v",
    ]
