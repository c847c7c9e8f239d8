"""Withdrawing a participant: kept and marked, audited, no more sessions,
left out of the analysis with the reason, still in the export."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.audit import AuditEntry
from db.models.study import Participant
from study.cli import main
from study.protocol.design import parse_design
from study.protocol.roster import create_study
from tests.study.conftest import one_error_line
from tests.study.tui.conftest import DESIGN, PEAKS, store_trials


@pytest.fixture
def db(tmp_path: Path) -> str:
    """P001-P006 (three novices, three experts), one completed trial per condition."""
    from study.protocol.roster import add_participant

    url = str(tmp_path / "study.db")
    engine = open_database(url, create=True)
    create_study(engine, parse_design(DESIGN), DESIGN)
    add_participant(engine, "novice")
    add_participant(engine, "expert")
    store_trials(engine)
    engine.dispose()
    return url


def test_withdrawal_is_kept_audited_and_left_out_of_the_analysis(
    db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = open_database(db)
    with Session(engine) as session:
        novices = session.scalars(
            select(Participant.code).where(Participant.group == "novice").order_by(Participant.code)
        ).all()
    code = novices[0]
    assert (
        main(
            [
                "participant",
                "withdraw",
                code,
                "--reason",
                "felt unwell",
                "--actor",
                "EXP02",
                "--db",
                db,
            ]
        )
        == 0
    )
    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == code)).one()
        entry = session.scalars(select(AuditEntry).where(AuditEntry.field == "status")).one()
    assert p.withdrawn_at is not None
    assert p.withdrawal_reason == "felt unwell"
    assert (entry.old_value, entry.new_value, entry.reason, entry.actor) == (
        "enrolled",
        "withdrawn",
        "felt unwell",
        "EXP02",
    )
    # the analysis leaves them out and says why; the novice n drops from 3 to 2
    out = tmp_path / "res.json"
    assert main(["analyze", "--out", str(tmp_path / "res"), "--json", str(out), "--db", db]) == 0
    report = json.loads(out.read_text())
    assert f"lcca/all measures: excluded {code} (withdrawn: felt unwell)" in report["exclusions"]
    [peak] = [
        d
        for d in report["descriptives"]
        if d["measure"] == "peak_proximal_force_n"
        and d["group"] == "novice"
        and d["condition"] == "VO"
    ]
    assert peak["n"] == 2
    # the remaining novices' VO mean, by hand from the stored peaks (the first one left)
    vo = PEAKS[("novice", "VO")]
    others = [v for k, v in enumerate(vo) if novices[k] != code]
    assert peak["mean"] == pytest.approx(sum(others) / 2)
    assert "lcca/peak_proximal_force_n/novice: n = 2 pairs, too few to test" in report["exclusions"]
    # their trials stay in the database and in the export
    exported = tmp_path / "export"
    assert main(["export", "--out", str(exported), "--db", db]) == 0
    trials = pd.read_csv(exported / "trials.csv")
    assert (trials["participant"] == code).sum() == 2
    # no more sessions for them
    line = one_error_line(capsys, ["run", "--participant", code, "--db", db])
    assert line.endswith(
        f"participant {code} withdrew (felt unwell); expected a participant still in the study"
    )
    engine.dispose()


def test_bad_withdrawals_are_one_line(db: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert "P999" in one_error_line(
        capsys, ["participant", "withdraw", "P999", "--reason", "x", "--db", db]
    )
    assert "expected 1-500 characters" in one_error_line(
        capsys, ["participant", "withdraw", "P001", "--reason", "  ", "--db", db]
    )
    assert main(["participant", "withdraw", "P001", "--reason", "moved away", "--db", db]) == 0
    capsys.readouterr()
    again = ["participant", "withdraw", "P001", "--reason", "again", "--db", db]
    line = one_error_line(capsys, again)
    assert "P001 withdrew on" in line
    assert "(moved away)" in line


def test_a_note_is_kept_and_its_edits_audited(db: str) -> None:
    assert main(["participant", "note", "P002", "prefers the left hand", "--db", db]) == 0
    assert main(["participant", "note", "P002", "left-handed grip", "--db", db]) == 0
    engine = open_database(db)
    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == "P002")).one()
        edits = session.scalars(select(AuditEntry).where(AuditEntry.field == "note")).all()
    engine.dispose()
    assert p.note == "left-handed grip"
    assert [(e.old_value, e.new_value) for e in edits] == [
        (None, "prefers the left hand"),
        ("prefers the left hand", "left-handed grip"),
    ]


def test_session_notes_are_added_beside_the_participants_note(db: str) -> None:
    assert main(["participant", "note", "P002", "left-handed grip", "--db", db]) == 0
    for text in ("dial recalibrated after trial 2", "fire alarm: 5 min pause"):
        assert main(["participant", "note", "P002", text, "--session", "--db", db]) == 0
    assert main(["participant", "note", "P009", "x", "--session", "--db", db]) == 2
    engine = open_database(db)
    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == "P002")).one()
        notes = session.scalars(
            select(AuditEntry).where(AuditEntry.field == "session_note").order_by(AuditEntry.id)
        ).all()
    engine.dispose()
    # the participant's note stays; each session note is its own row, none replaced
    assert p.note == "left-handed grip"
    assert [(n.entity_id, n.old_value, n.new_value) for n in notes] == [
        (p.id, None, "dial recalibrated after trial 2"),
        (p.id, None, "fire alarm: 5 min pause"),
    ]
    assert all(n.reason.startswith("note on the session of 20") for n in notes)


def test_a_participant_withdrawn_before_any_trial_is_listed_in_the_exclusions(
    db: str, tmp_path: Path
) -> None:
    from study.protocol.roster import add_participant

    engine = open_database(db)
    code = add_participant(engine, "expert").code  # enrolled, never run
    engine.dispose()
    assert (
        main(["participant", "withdraw", code, "--reason", "changed their mind", "--db", db]) == 0
    )
    out = tmp_path / "res.json"
    assert main(["analyze", "--out", str(tmp_path / "res"), "--json", str(out), "--db", db]) == 0
    report = json.loads(out.read_text())
    assert (
        f"all tasks: excluded {code} (withdrawn: changed their mind; no data stored)"
        in report["exclusions"]
    )
