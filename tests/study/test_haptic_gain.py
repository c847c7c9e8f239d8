"""The haptic dial's gain per condition: set in the design, used by `study run` (and so by
the TUI, which runs the same session), refused where it cannot apply."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.trial import Trial
from study.cli import main
from study.errors import StudyInputError
from study.protocol.design import TEMPLATE, parse_design
from study.protocol.tasks import get_task
from teleop_core.master.params import HapticParams

BASE = 'name = "g"\nseed = 2\ntrials_per_condition = 1\npractice_trials = 0\n'


def test_the_default_is_the_papers_gain() -> None:
    assert get_task("lcca").default_haptic_gain_n_m_per_n == HapticParams().haptic_gain_n_m_per_n
    # the template states the paper's gain
    assert parse_design(TEMPLATE).haptic_gain_for("HV") == HapticParams().haptic_gain_n_m_per_n
    assert parse_design(BASE + "[groups]\nnovice = 1\n").haptic_gain_for("HV") is None


@pytest.mark.parametrize(
    "table, message",
    [
        ("VO = 0.02", "haptic_gain_n_m_per_n.VO = 0.02; expected 0 (Visual-Only renders no force)"),
        ("XX = 0.01", "haptic_gain_n_m_per_n.XX names no condition of the design"),
        ("HV = -0.01", "haptic_gain_n_m_per_n.HV = -0.01; expected 0 to 1 N m/N"),
        ("HV = 'high'", "haptic_gain_n_m_per_n.HV = 'high'; expected a number (N m/N)"),
        ("HV = inf", "haptic_gain_n_m_per_n.HV = inf; expected 0 to 1 N m/N"),
    ],
)
def test_a_bad_gain_is_refused_with_one_line(table: str, message: str) -> None:
    text = BASE + f"[groups]\nnovice = 1\n[haptic_gain_n_m_per_n]\n{table}\n"
    with pytest.raises(StudyInputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_design(text)


def test_study_run_uses_the_designs_gain_in_hv(tmp_path: Path) -> None:
    db = str(tmp_path / "s.db")
    (tmp_path / "d.toml").write_text(
        BASE + "[groups]\nexpert = 1\n[haptic_gain_n_m_per_n]\nHV = 0.013\n"
    )
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    assert main(["participant", "add", "--group", "expert", "--db", db]) == 0
    assert main(["run", "--participant", "P001", "--db", db]) == 0
    engine = open_database(db)
    with Session(engine) as session:
        gains = {
            t.condition: t.summary.get("haptic_gain_n_m_per_n")
            for t in session.scalars(select(Trial))
        }
    engine.dispose()
    # HV at the design's gain; VO renders nothing
    assert gains == {"HV": 0.013, "VO": 0.0}


def test_simulate_refuses_a_gain_for_a_task_without_a_dial(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "t.csv"
    argv = [
        "simulate",
        "--task",
        "notes",
        "--group",
        "expert",
        "--condition",
        "HV",
        "--haptic-gain",
        "2",
        "--out",
        str(out),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "study simulate: error: haptic gain 2.0 for the notes task, which has no haptic "
        "dial; expected no gain for it"
    ]
    assert not out.exists()


@pytest.mark.parametrize("gain", [1.0000001, 1e9, -0.01, float("nan"), float("inf")])
def test_the_task_refuses_a_gain_outside_the_design_files_bound(gain: float) -> None:
    # every caller (simulate, sessions, campaigns) goes through Task.haptic_gain
    with pytest.raises(StudyInputError, match=r"expected 0 to 1 N m/N"):
        get_task("lcca").haptic_gain(gain)


def test_the_task_accepts_the_bound_itself() -> None:
    assert get_task("lcca").haptic_gain(1.0) == 1.0


def test_simulate_records_the_vo_gain_as_the_session_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """VO renders no haptic torque: `study simulate` records its gain as 0, as a session's
    VO trial does, and refuses a gain given with VO."""
    import json

    base = ["simulate", "--group", "expert", "--max-seconds", "2", "--seed", "3"]
    assert main([*base, "--condition", "VO", "--out", str(tmp_path / "vo.csv")]) == 0
    assert json.loads((tmp_path / "vo.json").read_text())["haptic_gain_n_m_per_n"] == 0.0
    assert main([*base, "--condition", "HV", "--out", str(tmp_path / "hv.csv")]) == 0
    hv = json.loads((tmp_path / "hv.json").read_text())
    assert hv["haptic_gain_n_m_per_n"] == HapticParams().haptic_gain_n_m_per_n
    capsys.readouterr()
    bad = tmp_path / "bad.csv"
    assert main([*base, "--condition", "VO", "--haptic-gain", "0.03", "--out", str(bad)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "study simulate: error: --haptic-gain 0.03 with VO; VO renders no haptic torque "
        "(expected the gain with HV only)"
    ]
    assert not bad.exists()
