"""The task registry and the built-in tasks' declarations, against the loops they name."""

from __future__ import annotations

import pytest

from study.errors import StudyInputError
from study.protocol.tasks import described, get_task, task_names
from teleop_core.loop import layout
from teleop_core.loop.layout import SAMPLE_COLUMNS as LOOP_COLUMNS
from teleop_core.notes import task as notes


def test_the_builtin_tasks_are_known_and_an_unknown_one_gets_one_line() -> None:
    assert task_names()[:2] == ("lcca", "notes")
    with pytest.raises(
        StudyInputError,
        match=r"^task 'endo' is not installed: pip install the package whose "
        r"haptic_study.tasks entry point is 'endo'; installed: lcca, notes",
    ):
        get_task("endo")
    # the worked example's package ships with haptic-study: the line says how to install it
    with pytest.raises(
        StudyInputError,
        match=r"^task 'probe' is not installed: study example-data DIR && pip install "
        r"DIR/probe_task;",
    ):
        get_task("probe")


def test_the_lcca_task_stores_the_loops_columns_in_order_under_the_loops_names() -> None:
    lcca = get_task("lcca")
    # one name per quantity from the loop to the database: the loop's row, column by
    # column, as the kernel writes it (S_* indices)
    assert tuple(c.name for c in lcca.sample_columns) == LOOP_COLUMNS
    columns = {c.name: c for c in lcca.sample_columns}
    assert LOOP_COLUMNS[layout.S_PROXIMAL] == "reference_force_n"
    assert LOOP_COLUMNS[layout.S_PROXIMAL_EST] == "proximal_force_n"
    assert "estimated" in columns["proximal_force_n"].description
    assert "true" in columns["reference_force_n"].description
    assert [columns[n].unit for n in ("t_s", "dial_torque_n_m", "branch")] == ["s", "N m", ""]
    # the branch names as the phantom's sample rows and the database store them
    assert lcca.regions == ("DAo", "arch", "AAo", "LSA", "LCCA", "BCT")


def test_the_notes_task_names_the_notes_loops_columns() -> None:
    task = get_task("notes")
    assert tuple(c.name for c in task.sample_columns) == notes.SAMPLE_COLUMNS
    assert task.region_column == "region"
    assert task.sample_columns[-1].name == "torque_demanded_n_m"
    assert task.sample_columns[-1].unit == "N m"

    # the regions the NOTES loop writes as the tip's place, by index
    assert task.regions == ("canal", "fornix", "cavity", "target", "fold")
    assert not task.has_dial
    assert get_task("lcca").has_dial


def test_every_measure_has_its_unit_in_its_name() -> None:
    suffix = {"N": "_n", "N m": "_n_m", "s": "_s", "": ""}
    for name in task_names():
        for m in get_task(name).all_measures:
            assert m.name.endswith(suffix[m.unit]) or m.unit == "", (name, m.name)


def test_a_layout_and_meanings_that_disagree_fail_where_the_task_is_declared() -> None:
    meanings = {"t_s": ("s", "time"), "x_m": ("m", "depth")}
    assert [c.unit for c in described(("t_s", "x_m"), meanings)] == ["s", "m"]
    with pytest.raises(ValueError, match=r"layout's \['y_m'\] have no meaning"):
        described(("t_s", "x_m", "y_m"), meanings)
    with pytest.raises(ValueError, match=r"meanings of \['x_m'\] name no column"):
        described(("t_s",), meanings)
