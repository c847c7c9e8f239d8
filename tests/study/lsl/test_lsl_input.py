"""The `[lsl]` table and the LSL options: bad input is one line, exit 2, nothing run."""

from __future__ import annotations

from pathlib import Path

import pytest

from study.cli import main
from study.errors import StudyInputError
from study.lsl.config import ENV, is_loopback_only
from study.protocol.design import LslSettings, parse_design
from tests.study.conftest import init_study


def test_the_lsl_table_reads_and_round_trips() -> None:
    design = parse_design('[lsl]\npublish = true\nrecord = ["type=\'EMG\'"]\nplot = ["EMG"]\n')
    assert design.lsl == LslSettings(True, ("type='EMG'",), ("EMG",))
    assert type(design).from_dict(design.to_dict()).lsl == design.lsl
    # a design without the table stores as before (no `lsl` key) and has LSL off
    plain = parse_design('name = "no instruments"\n')
    assert "lsl" not in plain.to_dict()
    assert plain.lsl == LslSettings()


@pytest.mark.parametrize(
    ("table", "named"),
    [
        ("publish = 1", "lsl.publish = 1"),
        ('record = "type=EMG"', "lsl.record = 'type=EMG'"),
        ('record = [""]', "lsl.record = ['']"),
        ("plot = [1]", "lsl.plot = [1]"),
        ("stream = true", "unknown key lsl.stream"),
    ],
)
def test_a_bad_lsl_table_names_the_key_and_value(table: str, named: str) -> None:
    with pytest.raises(StudyInputError, match="expected") as info:
        parse_design(f"[lsl]\n{table}\n")
    assert named in str(info.value)


def _one_line(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    assert main(list(args)) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_lsl_without_a_liblsl_config_is_one_line_and_runs_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    db = init_study(tmp_path, None, ("novice",))
    monkeypatch.delenv(ENV)
    line = _one_line(capsys, "run", "--participant", "P001", "--lsl", "--db", db)
    assert "LSLAPICFG=None; expected the path of a liblsl configuration file" in line
    line = _one_line(capsys, "run", "--all", "--lsl", "--db", db)
    assert "--lsl with --all" in line
    from sqlalchemy import create_engine, func, select

    from db.models.trial import Trial

    engine = create_engine(f"sqlite:///{db}")
    with engine.connect() as conn:  # no trial row was started
        assert conn.scalar(select(func.count()).select_from(Trial)) == 0
    engine.dispose()


def test_recording_needs_a_session_at_real_time(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    design = "[groups]\nnovice = 1\n[lsl]\nrecord = [\"type='EMG'\"]\n"
    db = init_study(tmp_path, design, ("novice",))
    line = _one_line(capsys, "run", "--participant", "P001", "--db", db)
    assert "[lsl] record with an unpaced simulated session" in line
    assert "--pace" in line


def test_lsl_config_writes_a_loopback_only_file_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "lsl_api.cfg"
    assert main(["lsl-config", str(path)]) == 0
    assert is_loopback_only(path)
    assert "exists" in _one_line(capsys, "lsl-config", str(path))


def test_run_all_says_it_leaves_the_lsl_table_aside(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    design = "trials_per_condition = 1\npractice_trials = 0\n[groups]\nnovice = 1\n"
    db = init_study(tmp_path, design + "[lsl]\npublish = true\n", ("novice",))
    assert main(["run", "--all", "--db", db]) == 0
    err = capsys.readouterr().err
    assert "[lsl] streams are published and recorded by one participant's session" in err
