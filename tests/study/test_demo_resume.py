"""`study demo` killed halfway (SIGKILL, as a power cut or a closed laptop ends it) and
run again with the same command in the same folder: the demo is continued, not refused
or replaced, every trial completed before the kill is kept as it was, and the study in
the end is the whole quick design. In between, `study schedule` says the demo is
incomplete."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path

import pytest

from study.cli import main

# the quick demo: 2/2/2 participants, lcca, VO and HV, one measured trial per block
QUICK_PARTICIPANTS = 6
QUICK_CONDITIONS = 2

pytestmark = pytest.mark.slow


def _argv(out: Path) -> list[str]:
    return ["demo", "--quick", "--out", str(out), "--seed", "3", "--jobs", "1"]


def _run(out: Path) -> subprocess.Popen[str]:
    code = f"from study.cli import main; raise SystemExit(main({_argv(out)!r}))"
    return subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def _completed(db: Path) -> list[tuple[object, ...]]:
    """The completed trials as stored: who, which block and trial, when, what it measured."""
    if not db.exists():
        return []
    try:
        with closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=1)) as conn:
            return conn.execute(
                "SELECT t.id, p.code, t.task, t.condition, t.block_index, t.trial_index, "
                "t.practice, t.attempt, t.ended_at, t.completion_time_s, t.success "
                "FROM trials t JOIN participants p ON p.id = t.participant_id "
                "WHERE t.status = 'completed' ORDER BY t.id"
            ).fetchall()
    except sqlite3.OperationalError:  # not yet created, or the schema not yet there
        return []


def test_a_killed_demo_is_continued_by_the_same_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "demo"
    db = out / "demo.db"
    first = _run(out)
    deadline = time.monotonic() + 240
    try:
        while len(_completed(db)) < 4:
            assert first.poll() is None, f"the demo ended before it was killed: {first.stderr}"
            assert time.monotonic() < deadline, "no four trials completed in 240 s"
            time.sleep(0.2)
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
    before = _completed(db)
    assert before, "nothing completed before the kill"

    # the half-finished database says what it is
    capsys.readouterr()
    assert main(["schedule", "--db", str(db)]) == 0
    assert "INCOMPLETE demo" in capsys.readouterr().out
    assert main(["schedule", "--db", str(db), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["incomplete_demo"] is True

    second = _run(out)
    _, err = second.communicate(timeout=600)
    assert second.returncode == 0, err
    assert "continuing the incomplete demo" in err

    after = _completed(db)
    # no trial completed before the kill is lost or changed
    assert set(before) <= set(after)
    measured = [row for row in after if not row[6]]
    keys = {(row[1], row[3], row[4], row[5]) for row in measured}
    assert len(keys) == len(measured), "a measured trial stored twice"
    assert len(measured) == QUICK_PARTICIPANTS * QUICK_CONDITIONS
    with closing(sqlite3.connect(db)) as conn:
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert conn.execute("PRAGMA foreign_key_check").fetchall() == []
        (n_tlx,) = conn.execute("SELECT count(*) FROM tlx_responses").fetchone()
    assert n_tlx == QUICK_PARTICIPANTS * QUICK_CONDITIONS  # one per block, none twice

    assert main(["schedule", "--db", str(db), "--json"]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["incomplete_demo"] is False
    assert (out / "analysis" / "analysis.json").is_file()
    # complete now: the same command again is refused, never a second demo over it
    assert main(_argv(out)) == 2
