"""A lab day of ten participants in three groups, in a real terminal (tmux, 80 x 24), by
keyboard only; the database compared field by field with what was typed
(tests/study/tui/lab_day.py, which also runs as a script with more participants)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.study.tui.lab_day import TASK_BLOCKS, compare, run_lab_day


@pytest.mark.skipif(shutil.which("tmux") is None, reason="needs tmux, a real terminal")
@pytest.mark.timeout(600)
def test_a_lab_day_of_ten_participants_typed_by_keyboard(tmp_path: Path) -> None:
    result = run_lab_day(tmp_path, participants=10, pace=200.0, seed=0)
    typed = result["typed"]
    assert sorted(typed.groups.values()).count("outsider") == 4
    assert set(typed.groups.values()) == {"outsider", "novice", "expert"}
    # every block of every participant run; every questionnaire typed and saved but
    # the last one, typed in part and left unsaved (quitting named it)
    assert sum(map(len, typed.blocks.values())) == 10 * len(TASK_BLOCKS)
    assert len(typed.tlx) == 10 * len(TASK_BLOCKS) - 1
    assert typed.unsaved not in typed.tlx
    assert compare(result["db"], typed) == []
