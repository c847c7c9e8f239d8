"""Audited corrections from the command line: a measured trial marked invalid (kept, left
out of the analysis with its reason) and valid again, a withdrawal undone, a wrong group
corrected before the first trial. Each is an audit row with who, when and why; each
refusal is one line with exit status 2 and changes nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.audit import AuditEntry
from db.models.study import Participant, ScheduleBlock
from db.models.trial import Trial
from study.cli import main
from study.protocol.design import parse_design
from study.protocol.roster import create_study
from tests.study.conftest import one_error_line
from tests.study.tui.conftest import DESIGN, PEAKS, store_trials


@pytest.fixture
def db(db_url: str) -> str:
    """P001-P006 (three novices, three experts), one completed trial per condition, on
    each backend."""
    from study.protocol.roster import add_participant

    url = db_url
    engine = open_database(url, create=True)
    create_study(engine, parse_design(DESIGN), DESIGN)
    add_participant(engine, "novice")
    add_participant(engine, "expert")
    store_trials(engine)
    engine.dispose()
    return url


def _audit(db: str, entity: str, field: str) -> list[AuditEntry]:
    engine = open_database(db)
    with Session(engine) as session:
        rows = session.scalars(
            select(AuditEntry)
            .where(AuditEntry.entity == entity, AuditEntry.field == field)
            .order_by(AuditEntry.id)
        ).all()
        session.expunge_all()
    engine.dispose()
    return list(rows)


def _novice_vo(db: str) -> list[tuple[int, str, float]]:
    """(trial id, code, peak) of the novices' VO trials, in code order."""
    engine = open_database(db)
    with Session(engine) as session:
        rows = session.execute(
            select(Trial, Participant.code)
            .join(Participant)
            .where(Participant.group == "novice", Trial.condition == "VO")
            .order_by(Participant.code)
        ).all()
        out = [(t.id, code, t.measure_values["peak_proximal_force_n"]) for t, code in rows]
    engine.dispose()
    return out


def _analyze(db: str, tmp_path: Path) -> tuple[dict, str]:
    out = tmp_path / "res.json"
    assert main(["analyze", "--out", str(tmp_path / "res"), "--json", str(out), "--db", db]) == 0
    return json.loads(out.read_text()), (tmp_path / "res" / "methods.md").read_text()


def _novice_vo_peak(report: dict) -> dict:
    [row] = [
        d
        for d in report["descriptives"]
        if d["measure"] == "peak_proximal_force_n"
        and d["group"] == "novice"
        and d["condition"] == "VO"
    ]
    return row


def test_an_invalid_trial_is_kept_audited_left_out_and_listed_then_valid_again(
    db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (trial_id, code, _), *rest = _novice_vo(db)
    argv = ["trial", "invalidate", str(trial_id), "--reason", "dial slipped", "--db", db]
    assert main([*argv, "--actor", "EXP02"]) == 0
    assert "marked invalid (dial slipped)" in capsys.readouterr().out
    [row] = _audit(db, "trial", "validity")
    assert (row.entity_id, row.old_value, row.new_value, row.reason, row.actor) == (
        trial_id,
        "valid",
        "invalid",
        "dial slipped",
        "EXP02",
    )
    assert row.at is not None
    # the analysis leaves it out and lists it with its reason, in analysis.json and methods
    report, methods = _analyze(db, tmp_path)
    listed = f"lcca/all measures: excluded {code} VO trial 1 (marked invalid: dial slipped)"
    assert listed in report["exclusions"]
    assert f"left out: {code} VO trial 1 (dial slipped)." in methods
    peak = _novice_vo_peak(report)
    # the other two novices' VO peaks, from PEAKS by hand: (1.2 + 1.4) / 2
    assert peak["n"] == 2
    assert peak["mean"] == pytest.approx((1.2 + 1.4) / 2)
    assert [p for _, _, p in rest] == [1.2, 1.4]
    # kept in the database and in the export
    exported = tmp_path / "export"
    assert main(["export", "--out", str(exported), "--db", db]) == 0
    trials = pd.read_csv(exported / "trials.csv")
    assert ((trials["participant"] == code) & (trials["condition"] == "VO")).sum() == 1
    # the trial list shows it
    capsys.readouterr()
    assert main(["trial", "list", "--participant", code, "--db", db]) == 0
    listed = capsys.readouterr()
    listing = listed.out
    assert f"{trial_id:>6} lcca/VO trial 1 attempt 1: completed" in listing
    assert "INVALID (dial slipped)" in listing
    assert listed.err == ""
    # the older positional form lists the same, with a deprecation warning
    assert main(["trial", "list", code, "--db", db]) == 0
    old_form = capsys.readouterr()
    assert old_form.out == listing
    assert "deprecated" in old_form.err
    assert f"--participant {code}" in old_form.err
    # twice: one line, nothing changed
    line = one_error_line(capsys, argv)
    assert line.endswith(
        f"trial {trial_id} ({code} lcca/VO trial 1 (attempt 1)) is already marked invalid "
        "(dial slipped); expected a valid trial"
    )
    assert len(_audit(db, "trial", "validity")) == 1
    # valid again: audited, counted again
    back = ["trial", "revalidate", str(trial_id), "--reason", "video shows it was fine"]
    assert main([*back, "--db", db]) == 0
    rows = _audit(db, "trial", "validity")
    assert [(r.old_value, r.new_value, r.reason) for r in rows] == [
        ("valid", "invalid", "dial slipped"),
        ("invalid", "valid", "video shows it was fine"),
    ]
    report, methods = _analyze(db, tmp_path)
    assert not any("marked invalid" in e for e in report["exclusions"])
    assert "marked invalid" not in methods
    assert _novice_vo_peak(report)["n"] == 3
    assert _novice_vo_peak(report)["mean"] == pytest.approx(sum(PEAKS[("novice", "VO")]) / 3)
    assert "is valid; expected an invalid trial" in one_error_line(capsys, [*back, "--db", db])


def test_trial_corrections_refused_in_one_line(db: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert one_error_line(
        capsys, ["trial", "invalidate", "9999", "--reason", "x", "--db", db]
    ).endswith("unknown trial id 9999; expected an id from `study trial list --participant CODE`")
    assert "expected 1-500 characters" in one_error_line(
        capsys, ["trial", "invalidate", "1", "--reason", " ", "--db", db]
    )
    assert "--reason" in one_error_line(capsys, ["trial", "invalidate", "1", "--db", db])
    # an interrupted trial is not a measured result: nothing to mark
    engine = open_database(db)
    with Session(engine) as session:
        t = session.scalars(select(Trial).order_by(Trial.id)).first()
        t.status = "interrupted"
        session.commit()
        tid = t.id
    engine.dispose()
    line = one_error_line(capsys, ["trial", "invalidate", str(tid), "--reason", "x", "--db", db])
    assert line.endswith("is interrupted; expected a completed measured trial")
    assert _audit(db, "trial", "validity") == []


def test_a_withdrawal_is_undone_audited_and_counted_again(
    db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = _novice_vo(db)[0][1]
    assert main(["participant", "withdraw", code, "--reason", "felt unwell", "--db", db]) == 0
    undo = ["participant", "reinstate", code, "--reason", "recovered after a break"]
    assert main([*undo, "--actor", "EXP03", "--db", db]) == 0
    assert f"{code} is in the study again" in capsys.readouterr().out
    rows = _audit(db, "participant", "status")
    assert [(r.old_value, r.new_value, r.reason) for r in rows] == [
        ("enrolled", "withdrawn", "felt unwell"),
        ("withdrawn", "enrolled", "recovered after a break"),
    ]
    assert rows[1].actor == "EXP03"
    engine = open_database(db)
    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == code)).one()
        assert (p.withdrawn_at, p.withdrawal_reason) == (None, None)
    engine.dispose()
    report, _ = _analyze(db, tmp_path)
    assert not any("withdrawn" in e for e in report["exclusions"])
    assert _novice_vo_peak(report)["n"] == 3
    line = one_error_line(capsys, [*undo, "--db", db])
    assert line.endswith(f"participant {code} is not withdrawn; expected a withdrawn participant")
    assert len(_audit(db, "participant", "status")) == 2


def test_a_wrong_group_is_corrected_before_the_first_trial_only(
    db: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from study.protocol.design import next_order

    assert main(["participant", "add", "--group", "novice", "--beyond-target", "--db", db]) == 0
    new = capsys.readouterr().out.split()[0]
    engine = open_database(db)
    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == new)).one()
        old_order = list(p.condition_order)
        experts = [
            tuple(o)
            for o in session.scalars(
                select(Participant.condition_order).where(Participant.group == "expert")
            )
        ]
    engine.dispose()
    # the expert group is full (2 of 2 targeted, 3 enrolled): refused without --beyond-target
    fix = ["participant", "correct-group", new, "--group", "expert", "--reason", "misfiled"]
    line = one_error_line(capsys, [*fix, "--db", db])
    assert "group expert has its 2 participants" in line
    assert main([*fix, "--beyond-target", "--actor", "EXP02", "--db", db]) == 0
    # the order the expert group's counterbalancing gives its next member
    expected = next_order(parse_design(DESIGN), "expert", experts)
    assert capsys.readouterr().out.strip() == (
        f"{new} (expert): conditions {' then '.join(expected)} (misfiled)"
    )
    engine = open_database(db)
    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == new)).one()
        blocks = session.scalars(
            select(ScheduleBlock)
            .where(ScheduleBlock.participant_id == p.id)
            .order_by(ScheduleBlock.block_index)
        ).all()
        assert (p.group, list(p.condition_order)) == ("expert", list(expected))
        assert [b.condition for b in blocks] == list(expected)
    engine.dispose()
    [row] = _audit(db, "participant", "group")
    assert json.loads(row.old_value) == {"group": "novice", "condition_order": old_order}
    assert json.loads(row.new_value) == {"group": "expert", "condition_order": list(expected)}
    assert (row.reason, row.actor) == ("misfiled", "EXP02")
    # a participant with trials: one line, nothing changed
    line = one_error_line(
        capsys,
        ["participant", "correct-group", "P001", "--group", "expert", "--reason", "x", "--db", db],
    )
    assert line.endswith(
        "participant P001 has 2 trials stored in the novice group; expected a participant "
        "before their first trial (withdraw them and enrol anew)"
    )
    assert "unknown group 'pilot'" in one_error_line(
        capsys, [*fix[:3], "--group", "pilot", "--reason", "x", "--db", db]
    )
    assert len(_audit(db, "participant", "group")) == 1
