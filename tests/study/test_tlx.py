"""NASA-TLX scoring, the pairwise comparisons, storage and the audit trail."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.audit import AuditEntry
from study.cli import main
from study.errors import StudyInputError
from study.protocol.design import TEMPLATE, parse_design
from study.protocol.roster import add_participant, create_study
from study.protocol.tlx import (
    PAIRS,
    check_rating,
    pair_order,
    raw_tlx,
    store_tlx,
    weighted_tlx,
    weights_from_choices,
)
from tests.study.conftest import init_study

RATINGS = {
    "mental": 70,
    "physical": 20,
    "temporal": 50,
    "performance": 30,
    "effort": 60,
    "frustration": 40,
}
WEIGHTS = {
    "mental": 5,
    "physical": 0,
    "temporal": 3,
    "performance": 2,
    "effort": 4,
    "frustration": 1,
}


def test_scores_by_hand() -> None:
    # raw: (70 + 20 + 50 + 30 + 60 + 40) / 6 = 45
    assert raw_tlx(RATINGS) == pytest.approx(45.0)
    # weighted: (5*70 + 0*20 + 3*50 + 2*30 + 4*60 + 1*40) / 15 = 840 / 15 = 56
    assert weighted_tlx(RATINGS, WEIGHTS) == pytest.approx(56.0)


@pytest.mark.parametrize("value", [-5, 57, 105, 2.5, True, "50"])
def test_off_scale_ratings_are_refused(value: object) -> None:
    with pytest.raises(StudyInputError, match="off the scale"):
        check_rating("effort", value)


def test_each_pair_is_shown_once_in_a_seeded_order_per_participant() -> None:
    a, b = pair_order(1, "P001"), pair_order(1, "P002")
    assert a == pair_order(1, "P001")
    assert a != b
    assert sorted(tuple(sorted(p)) for p in a) == sorted(tuple(sorted(p)) for p in PAIRS)


def test_weights_tally_the_choices() -> None:
    pairs = pair_order(1, "P001")
    # always pick the subscale that comes first in the form: mental wins all 5 of its pairs
    order = list(RATINGS)
    chosen = [min(p, key=order.index) for p in pairs]
    w = weights_from_choices(pairs, chosen)
    assert w == {
        "mental": 5,
        "physical": 4,
        "temporal": 3,
        "performance": 2,
        "effort": 1,
        "frustration": 0,
    }
    with pytest.raises(StudyInputError, match="choice 1"):
        weights_from_choices(pairs, ["nobody", *chosen[1:]])


def test_edits_keep_the_old_value_in_the_audit_log(db_url: str) -> None:
    engine = open_database(db_url)
    try:
        create_study(engine, parse_design(TEMPLATE), TEMPLATE)
        p = add_participant(engine, "novice")
        pairs = pair_order(1, p.code)
        chosen = [a for a, _ in pairs]
        with pytest.raises(StudyInputError, match="has no completed trial yet"):
            store_tlx(engine, p.code, "lcca", "HV", RATINGS, chosen)
        stored, new = store_tlx(
            engine, p.code, "lcca", "HV", RATINGS, chosen, reason="paper form before the block"
        )
        assert new
        assert sum(getattr(stored, f"w_{s}") for s in RATINGS) == 15
        edited, new = store_tlx(
            engine, p.code, "lcca", "HV", {**RATINGS, "effort": 65}, reason="typo"
        )
        assert not new
        assert edited.effort == 65
        assert edited.w_mental == stored.w_mental
        with Session(engine) as s:
            audit = s.scalars(select(AuditEntry).where(AuditEntry.entity == "tlx_response")).all()
        assert (audit[0].field, audit[0].old_value, audit[0].reason) == (
            "entered",
            None,
            "paper form before the block",
        )  # the first entry, with every value
        assert json.loads(audit[0].new_value)["effort"] == 60
        assert [(a.field, a.old_value, a.new_value, a.reason) for a in audit][1:] == [
            ("stored_before_block_ran", None, "0 completed trials", "paper form before the block"),
            ("effort", "60", "65", "typo"),
        ]
        with pytest.raises(StudyInputError, match="no lcca/XX block"):
            store_tlx(engine, p.code, "lcca", "XX", RATINGS)
    finally:
        engine.dispose()


def test_cli_refuses_an_off_scale_rating_and_stores_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = init_study(tmp_path, groups=("expert",))
    args = ["tlx", "enter", "--participant", "P001", "--task", "lcca", "--condition", "VO"]
    args += [f"--{k}={v}" for k, v in {**RATINGS, "mental": 57}.items()]
    capsys.readouterr()
    assert main([*args, "--db", db]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "study tlx enter: error: mental rating 57 is off the scale; expected 0-100 in steps of 5"
    ]
    assert main(["tlx", "show", "--json", "--db", db]) == 0
    assert capsys.readouterr().out.strip() == "[]"


def test_show_and_the_analysis_frame_give_the_hand_computed_scores(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One scorer behind `study tlx show` and `frames.tlx_frame`: raw 45, weighted 56."""
    import json
    import math

    from study.analysis.frames import tlx_frame

    db = init_study(tmp_path, groups=("expert", "expert"))
    # pick the subscale WEIGHTS ranks higher in every pair: the tallies are WEIGHTS
    chosen = [max(pair, key=WEIGHTS.__getitem__) for pair in pair_order(1, "P001")]
    assert weights_from_choices(pair_order(1, "P001"), chosen) == WEIGHTS
    ratings = [f"--{k}={v}" for k, v in RATINGS.items()]
    block = ["--task", "lcca", "--condition", "VO", "--reason", "paper form", "--db", db]
    assert (
        main(
            [
                "tlx",
                "enter",
                "--participant",
                "P001",
                *block,
                *ratings,
                "--choices",
                ",".join(chosen),
            ]
        )
        == 0
    )
    assert main(["tlx", "enter", "--participant", "P002", *block, *ratings]) == 0
    assert capsys.readouterr().out.splitlines()[-2:] == [
        "P001 lcca/VO: stored; raw TLX 45.0, weighted TLX 56.0",
        "P002 lcca/VO: stored; raw TLX 45.0",
    ]
    assert main(["tlx", "show", "--json", "--db", db]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert [(r["participant"], r["tlx_raw"], r["tlx_weighted"]) for r in shown] == [
        ("P001", pytest.approx(45.0), pytest.approx(56.0)),
        ("P002", pytest.approx(45.0), None),
    ]
    assert main(["tlx", "show", "--participant", "P001", "--db", db]) == 0
    assert capsys.readouterr().out.strip() == "P001 lcca/VO: raw 45.0, weighted 56.0"
    engine = open_database("sqlite:///" + db, create=False)
    try:
        frame = tlx_frame(engine).set_index("participant")
    finally:
        engine.dispose()
    assert frame.loc["P001", "tlx_raw"] == pytest.approx(45.0)
    assert frame.loc["P001", "tlx_weighted"] == pytest.approx(56.0)
    assert math.isnan(frame.loc["P002", "tlx_weighted"])
    assert frame.loc["P001", "tlx_mental"] == 70.0
