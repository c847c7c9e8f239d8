"""Study designs, counterbalancing and enrolment."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import pytest
from sqlalchemy import event, select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.study import Participant
from db.models.trial import Trial
from study.cli import main
from study.errors import StudyInputError
from study.protocol.design import TEMPLATE, StudyDesign, next_order, parse_design, williams_square
from study.protocol.roster import add_participant, create_study, schedule


def test_the_template_is_the_papers_design() -> None:
    d = parse_design(TEMPLATE)
    assert d.groups == {"outsider": 20, "novice": 8, "expert": 8}
    assert d.conditions == ("VO", "HV")
    assert d.tasks == ("lcca",)
    assert d.orders == [("VO", "HV"), ("HV", "VO")]


@pytest.mark.parametrize(
    "text, message",
    [
        ("colour = 'red'", "unknown key 'colour'"),
        (
            "trials_per_condition = 'three'",
            "trials_per_condition = 'three'; expected a whole number",
        ),
        ("conditions = ['VO', 'XX']", "condition 'XX'"),
        ("[groups]\nnovice = 0", "groups.novice = 0; expected a whole number from 1 to 1000"),
        ("counterbalancing = 'latin-square'\nconditions = ['VO']", "expected at least two"),
        ("counterbalancing = 'random'", "counterbalancing = 'random'"),
        ("tasks = ['lcca', 'surgery']", "task 'surgery'"),
        ("code_prefix = 'p1'", "code_prefix = 'p1'"),
        ("name = ", "not valid TOML"),
    ],
)
def test_bad_designs_are_refused_with_the_key_named(text: str, message: str) -> None:
    with pytest.raises(StudyInputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_design(text)


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_williams_square_is_balanced(n: int) -> None:
    rows = williams_square(n)
    assert len(rows) == (n if n % 2 == 0 else 2 * n)
    # every treatment once per row, and equally often in every position
    for row in rows:
        assert sorted(row) == list(range(n))
    for pos in range(n):
        counts = [sum(1 for r in rows if r[pos] == t) for t in range(n)]
        assert len(set(counts)) == 1
    # every ordered pair of different treatments adjacent equally often (carry-over balance)
    pairs = [(r[i], r[i + 1]) for r in rows for i in range(n - 1)]
    counts = [pairs.count(p) for p in itertools.permutations(range(n), 2)]
    assert len(set(counts)) == 1


@pytest.mark.parametrize("conditions", [("VO", "HV")])
def test_orders_stay_balanced_as_a_group_fills(conditions: tuple[str, ...]) -> None:
    design = StudyDesign(conditions=conditions)
    used: list[tuple[str, ...]] = []
    for _ in range(21):
        used.append(next_order(design, "novice", used))
        counts = [used.count(o) for o in design.orders]
        assert max(counts) - min(counts) <= 1


def test_enrolment_gives_codes_orders_and_schedules(db_url: str) -> None:
    engine = open_database(db_url)
    try:
        design = parse_design(TEMPLATE)
        create_study(engine, design, TEMPLATE)
        people = [add_participant(engine, g) for g in ("novice", "novice", "expert", "novice")]
        assert [p.code for p in people] == ["P001", "P002", "P003", "P004"]
        novices = [tuple(p.condition_order) for p in people if p.group == "novice"]
        assert abs(novices.count(("VO", "HV")) - novices.count(("HV", "VO"))) <= 1
        plan = schedule(engine)
        assert plan["groups"]["novice"] == {"target": 8, "enrolled": 3}
        first = plan["participants"][0]
        assert [b["condition"] for b in first["blocks"]] == first["condition_order"]
        assert first["trials_planned"] == 2 * (design.practice_trials + 3)
        with pytest.raises(StudyInputError, match="unknown group 'surgeon'"):
            add_participant(engine, "surgeon")
        with pytest.raises(StudyInputError, match="already holds the study"):
            create_study(engine, design, TEMPLATE)
    finally:
        engine.dispose()


def _add_trials(engine, code: str, block_index: int, statuses: list[str]) -> None:
    with Session(engine) as session:
        p = session.scalars(select(Participant).where(Participant.code == code)).one()
        block = p.blocks[block_index]
        for k, status in enumerate(statuses):
            session.add(
                Trial(
                    participant_id=p.id,
                    block_id=block.id,
                    task=block.task,
                    condition=block.condition,
                    block_index=block_index,
                    trial_index=k,
                    status=status,
                )
            )
        session.commit()


def test_schedule_counts_each_participants_trials_in_a_fixed_number_of_queries(
    db_url: str,
) -> None:
    engine = open_database(db_url)
    queries: list[str] = []
    event.listen(engine, "before_cursor_execute", lambda *args: queries.append(args[2]))
    try:
        design = parse_design(TEMPLATE)
        create_study(engine, design, TEMPLATE)
        for group in ("novice", "expert"):
            add_participant(engine, group)
        _add_trials(engine, "P001", 0, ["completed", "completed", "interrupted"])
        _add_trials(engine, "P002", 1, ["completed"])
        queries.clear()
        plan = schedule(engine)
        few = len(queries)
        # hand counts of the rows just written, block by block
        progress = {
            r["code"]: [(b["completed"], b["interrupted"]) for b in r["blocks"]]
            for r in plan["participants"]
        }
        assert progress == {"P001": [(2, 1), (0, 0)], "P002": [(0, 0), (1, 0)]}
        assert [r["trials_completed"] for r in plan["participants"]] == [2, 1]
        for _ in range(10):
            add_participant(engine, "outsider")
        _add_trials(engine, "P012", 0, ["completed"])
        queries.clear()
        plan = schedule(engine)
        # twelve participants cost the same round trips as two (no query per participant)
        assert len(queries) == few
        assert [r["trials_completed"] for r in plan["participants"]] == [2, 1] + [0] * 9 + [1]
    finally:
        engine.dispose()


def test_cli_init_add_and_schedule(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = str(tmp_path / "s.db")
    assert main(["design", "template"]) == 0
    (tmp_path / "d.toml").write_text(capsys.readouterr().out)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    assert main(["participant", "add", "--group", "expert", "--db", db]) == 0
    assert "P001 (expert)" in capsys.readouterr().out
    assert main(["schedule", "--json", "--db", db]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["participants"][0]["code"] == "P001"
    (tmp_path / "bad.toml").write_text("trials_per_condition = 0\n")
    assert (
        main(["init", "--design", str(tmp_path / "bad.toml"), "--db", str(tmp_path / "b.db")]) == 2
    )
    assert not (tmp_path / "b.db").exists()  # nothing half-written
