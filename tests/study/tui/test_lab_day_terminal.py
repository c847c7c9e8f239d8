"""A lab day of six participants in three groups, in a real terminal (tmux, 80 x 24), by
keyboard only: a trial of each stopped with x and a reason typed character by character,
the Find field's hint words typed on the participants screen, the last participant
enrolled from the command line while the app runs, a raw-only questionnaire; the
database compared field by field with what was typed (tests/study/tui/lab_day.py, which
also runs as a script with more participants and a slower typist)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.study.tui.lab_day import HINT_WORDS, TASK_BLOCKS, compare, run_lab_day


@pytest.mark.skipif(shutil.which("tmux") is None, reason="needs tmux, a real terminal")
@pytest.mark.timeout(600)
def test_a_lab_day_of_six_participants_typed_by_keyboard(tmp_path: Path) -> None:
    # a short day for the suite: reasons typed in half a second, x within 2 s
    result = run_lab_day(
        tmp_path, participants=6, pace=200.0, seed=0, typing_s=0.5, stop_within_s=2.0
    )
    typed = result["typed"]
    assert sorted(typed.groups.values()).count("outsider") == 2
    assert set(typed.groups.values()) == {"outsider", "novice", "expert"}
    # every block of every participant run; every questionnaire typed and saved but
    # the last one, typed in part and left unsaved (quitting named it)
    assert sum(map(len, typed.blocks.values())) == 6 * len(TASK_BLOCKS)
    assert len(typed.tlx) == 6 * len(TASK_BLOCKS) - 1
    assert typed.unsaved not in typed.tlx
    # one stop a participant, each answered while the trial stood; one raw-only save
    assert sorted(typed.stops) == [f"P{k:03d}" for k in range(1, 7)]
    assert typed.lost_stops == []
    assert len(typed.raw_only) == 1
    assert set(typed.found) == set(HINT_WORDS)
    assert list(typed.cli) == ["P006"]  # on the list while the app ran
    # and the database holds what was typed (stops with their reasons, the raw-only
    # questionnaire without pairs, the search words opened nothing)
    assert compare(result["db"], typed) == []
