"""The audit log: an actor on every row, the pairwise choices
audited, a reason required for every edit."""

from __future__ import annotations

import getpass
import json
import socket
from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.engine import make_engine
from db.models.audit import AuditEntry
from db.models.tlx import TlxResponse
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.tlx import pair_order

RATINGS = {
    "mental": 70,
    "physical": 20,
    "temporal": 50,
    "performance": 30,
    "effort": 60,
    "frustration": 40,
}


def _enter(db: str, *extra: str, **ratings: int) -> int:
    args = ["tlx", "enter", "--participant", "P001", "--task", "lcca", "--condition", "VO"]
    args += [f"--{k}={v}" for k, v in {**RATINGS, **ratings}.items()]
    return main([*args, *extra, "--db", db])


def _audit(db: str, entity: str = "tlx_response") -> list[AuditEntry]:
    engine = make_engine(db)
    with Session(engine) as s:
        query = select(AuditEntry).order_by(AuditEntry.id)
        rows = s.scalars(query.where(AuditEntry.entity == entity)).all()
        s.expunge_all()
    engine.dispose()
    return list(rows)


def test_edits_need_a_reason_name_the_actor_and_audit_the_pairwise_choices(
    db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("STUDY_ACTOR", raising=False)
    (tmp_path / "d.toml").write_text(TEMPLATE)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db_url]) == 0
    assert main(["participant", "add", "--group", "expert", "--db", db_url]) == 0
    pairs = pair_order(1, "P001")
    first = [a for a, _ in pairs]
    assert _enter(db_url, "--choices", ",".join(first), "--reason", "paper form") == 0
    capsys.readouterr()
    created = _audit(db_url)  # the first entry, and why before its block ran
    assert [(r.field, r.reason) for r in created] == [
        ("entered", "paper form"),
        ("stored_before_block_ran", "paper form"),
    ]
    entered = json.loads(created[0].new_value)
    assert entered["participant"] == "P001"
    assert entered["mental"] == RATINGS["mental"]
    # an edit without a reason: one line, exit 2, nothing changed
    assert _enter(db_url, effort=65) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "needs a reason" in err[0]
    assert "P001 lcca/VO" in err[0]
    assert len(_audit(db_url)) == 2
    # the choices changed: the pairwise list is audited beside the weights it gives
    second = [b for _, b in pairs]
    assert (
        _enter(
            db_url,
            "--choices",
            ",".join(second),
            "--reason",
            "form misread",
            "--actor",
            "EXP02",
            effort=65,
        )
        == 0
    )
    rows = _audit(db_url)[2:]
    fields = {r.field: r for r in rows}
    assert "effort" in fields
    assert "pairwise" in fields
    assert [[a, b, c] for (a, b), c in zip(pairs, first, strict=True)] == json.loads(
        fields["pairwise"].old_value
    )
    assert json.loads(fields["pairwise"].new_value)[0][2] == second[0]
    assert {(r.actor, r.reason) for r in rows} == {("EXP02", "form misread")}
    engine = make_engine(db_url)
    with Session(engine) as s:
        stored = s.scalars(select(TlxResponse)).one()
        assert stored.pairwise[0][2] == second[0]
        assert stored.effort == 65
    engine.dispose()
    # the actor from STUDY_ACTOR, else the operating-system user and host
    monkeypatch.setenv("STUDY_ACTOR", "EXP07")
    assert _enter(db_url, "--reason", "re-entered", effort=70) == 0
    assert _audit(db_url)[-1].actor == "EXP07"
    monkeypatch.delenv("STUDY_ACTOR")
    assert _enter(db_url, "--reason", "re-entered", effort=75) == 0
    assert _audit(db_url)[-1].actor == f"{getpass.getuser()}@{socket.gethostname()}"[:64]
    capsys.readouterr()
    assert _enter(db_url, "--reason", "x", "--actor", "a" * 65, effort=80) == 2
    assert "--actor" in capsys.readouterr().err
