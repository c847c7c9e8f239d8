"""Two lab machines on one database: enrolling and running sessions at the same time."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.engine import make_engine
from db.models.study import Participant
from db.models.trial import Trial
from study.cli import main
from tests.study.conftest import stored_samples

DESIGN = """\
name = "two sites"
seed = 5
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 6
expert = 4
"""
CLI = [sys.executable, "-c", "from study.cli import main; raise SystemExit(main())"]


def _both(*argvs: list[str]) -> None:
    """Start the commands together, as two machines would, and wait for both."""
    procs = [
        subprocess.Popen([*CLI, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        for argv in argvs
    ]
    for proc in procs:
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err.decode()


def test_two_sites_enrol_and_run_at_once(db_url: str, tmp_path: Path) -> None:
    (tmp_path / "d.toml").write_text(DESIGN)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db_url]) == 0
    add = ["participant", "add", "--group", "novice", "--count", "3", "--db", db_url]
    _both([*add, "--site", "A"], [*add, "--site", "B"])
    engine = make_engine(db_url)
    try:
        with Session(engine) as s:
            people = s.scalars(select(Participant).order_by(Participant.code)).all()
            codes = [p.code for p in people]
            orders = [tuple(p.condition_order) for p in people]
        assert codes == [f"P{i:03d}" for i in range(1, 7)]  # unique, no gaps
        assert orders.count(("VO", "HV")) == orders.count(("HV", "VO")) == 3
        assert {p.site for p in people} == {"A", "B"}
        # each site runs its own participants' sessions at the same time
        _both(*[["run", "--participant", code, "--db", db_url] for code in ("P001", "P002")])
        with Session(engine) as s:
            trials = s.scalars(select(Trial).where(Trial.status == "completed")).all()
            assert sorted((t.participant_id, t.condition) for t in trials) == sorted(
                (p.id, c) for p in people[:2] for c in ("VO", "HV")
            )
            for t in trials:
                n = s.scalar(stored_samples(t.id))
                assert n == round(t.completion_time_s * 100)
    finally:
        engine.dispose()
