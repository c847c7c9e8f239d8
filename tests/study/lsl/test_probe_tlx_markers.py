"""Probe trials and stored questionnaires on the marker stream (the suite's loopback-only
liblsl config, tests/conftest.py): a marker inlet written here, as a lab's recorder."""

from __future__ import annotations

import uuid
from pathlib import Path

import pytest
from sqlalchemy.orm import Session

from db.migrate import open_database
from study.cli import main
from study.lsl.markers import parse
from study.lsl.observers import event_publisher
from study.probes.store import probe_frame
from study.protocol.roster import load_study
from study.protocol.tlx import store_tlx
from tests.study.conftest import init_study
from tests.study.lsl.test_session_streams import MarkerInlet

DESIGN = """\
name = "markers {tag}"
tasks = ["lcca"]
trials_per_condition = 1
practice_trials = 0
[probes]
reaction_time = 3
force_threshold = 4
[groups]
novice = 1
{lsl}
"""


def _markers(listener: MarkerInlet) -> list[dict]:
    listener.join(timeout=30)
    assert not listener.is_alive()
    return [parse(text) for _, text in listener.markers]


def test_probe_run_with_lsl_sends_a_marker_per_probe_trial(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the inlet below subscribes as soon as it finds the stream (a busy machine: slowly)
    monkeypatch.setattr("study.lsl.observers.SUBSCRIBE_S", 30.0)
    tag = uuid.uuid4().hex[:8]
    db = init_study(tmp_path, DESIGN.format(tag=tag, lsl=""), ("novice",))
    listener = MarkerInlet(f"haptic-study/markers {tag}/P001")
    listener.start()
    assert main(["probe", "run", "--participant", "P001", "--lsl", "--db", db]) == 0
    markers = _markers(listener)
    events = [m["event"] for m in markers]
    assert events == ["session_start"] + ["probe"] * 7 + ["session_end"]
    engine = open_database(db, create=False)
    stored = probe_frame(engine)
    engine.dispose()
    # the design's order: reaction_time's 3 trials, then force_threshold's 4
    assert [(m["probe"], m["trial_index"]) for m in markers[1:-1]] == [
        ("reaction_time", 0),
        ("reaction_time", 1),
        ("reaction_time", 2),
        ("force_threshold", 0),
        ("force_threshold", 1),
        ("force_threshold", 2),
        ("force_threshold", 3),
    ]
    for m in markers:
        assert (m["participant"], m["group"], m["study"]) == ("P001", "novice", f"markers {tag}")
    by_trial = {(r.probe, r.trial_index): r for r in stored.itertuples()}
    assert len(by_trial) == 7
    for m in markers[1:-1]:
        row = by_trial[(m["probe"], m["trial_index"])]
        assert m["stimulus"] == pytest.approx(row.stimulus)
        assert m["driver"] == "simulated" == row.driver
        assert (m["response"], m["correct"]) == (row.response, row.correct) or (
            m["response"] == pytest.approx(row.response) and m["correct"] == row.correct
        )


def test_a_stored_questionnaire_sends_one_marker_with_its_block(tmp_path: Path) -> None:
    tag = uuid.uuid4().hex[:8]
    design = DESIGN.format(tag=tag, lsl="[lsl]\npublish = true")
    db = init_study(tmp_path, design, ("novice",))
    engine = open_database(db, create=False)
    with Session(engine) as s:
        observer = event_publisher(load_study(s)[1], wait_for_consumers_s=30.0)
    assert observer is not None
    listener = MarkerInlet(f"haptic-study/markers {tag}/P001")
    listener.start()
    ratings = {
        "mental": 50,
        "physical": 20,
        "temporal": 35,
        "performance": 10,
        "effort": 60,
        "frustration": 5,
    }
    try:
        store_tlx(
            engine,
            "P001",
            "lcca",
            "HV",
            ratings,
            reason="entered before the block",
            observer=observer,
        )
    finally:
        observer.close()
        engine.dispose()
    markers = _markers(listener)
    assert [m["event"] for m in markers] == ["session_start", "questionnaire", "session_end"]
    q = markers[1]
    got = (q["participant"], q["group"], q["task"], q["condition"], q["new"])
    assert got == ("P001", "novice", "lcca", "HV", True)
    assert q["raw_tlx"] == pytest.approx((50 + 20 + 35 + 10 + 60 + 5) / 6)  # Hart & Staveland
    assert q["weighted_tlx"] is None  # no pairwise comparisons entered


def test_without_lsl_nothing_is_published(tmp_path: Path) -> None:
    db = init_study(tmp_path, DESIGN.format(tag="off", lsl=""), ("novice",))
    engine = open_database(db, create=False)
    with Session(engine) as s:
        assert event_publisher(load_study(s)[1]) is None
    engine.dispose()
