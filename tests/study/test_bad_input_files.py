"""Files and ids no command can use, each one line and exit status 2 (they were
tracebacks): a design or campaign file that is not UTF-8 text (`study power`,
`study campaign run`), an example-data folder that cannot be made, and a trial id
past what a database row can have."""

from __future__ import annotations

from pathlib import Path

import pytest

from study.cli import main
from tests.study.conftest import init_study


def _one_line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1, lines
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize(
    "content",
    [b"\xff\xfeb\x00i\x00n", "name = 'x'\n".encode("utf-16"), b"name = '\xe9'\n"],
    ids=["binary", "utf-16", "latin-1"],
)
@pytest.mark.parametrize(
    "argv",
    [["power", "--design", "{f}", "--n-sim", "10"], ["campaign", "run", "{f}", "--out", "{o}"]],
    ids=["power", "campaign run"],
)
def test_a_toml_file_that_is_not_utf8_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes, argv: list[str]
) -> None:
    path = tmp_path / "f.toml"
    path.write_bytes(content)
    out = tmp_path / "out"
    line = _one_line(capsys, [a.format(f=path, o=out) for a in argv])
    assert f"{path} is not UTF-8 text" in line, line
    assert "expected a UTF-8 TOML file" in line, line
    assert not out.exists()


def test_a_missing_design_file_for_power_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    line = _one_line(capsys, ["power", "--design", str(tmp_path / "absent.toml")])
    assert "absent.toml does not exist" in line, line


def test_example_data_into_a_folder_that_cannot_be_made_is_one_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # /proc exists and takes no new folder, whoever runs the tests
    if not Path("/proc/self").is_dir():
        pytest.skip("no /proc here")
    line = _one_line(capsys, ["example-data", "/proc/no-such-folder"])
    assert "/proc/no-such-folder cannot be written" in line, line
    assert not Path("/proc/no-such-folder").exists()


@pytest.mark.parametrize("command", ["invalidate", "revalidate"])
def test_a_trial_id_past_a_database_integer_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    db = init_study(tmp_path)
    before = Path(db).read_bytes()
    line = _one_line(capsys, ["trial", command, str(2**64), "--reason", "x", "--db", db])
    assert f"{2**64} is not in the range 1<=x<={2**63 - 1}" in line, line
    line = _one_line(capsys, ["trial", command, str(2**63 - 1), "--reason", "x", "--db", db])
    assert f"unknown trial id {2**63 - 1}" in line, line
    assert Path(db).read_bytes() == before


@pytest.fixture(scope="module")
def small_study(tmp_path_factory: pytest.TempPathFactory) -> str:
    design = (
        'name = "outputs"\ntasks = ["lcca"]\ntrials_per_condition = 1\npractice_trials = 0\n'
        "[groups]\nnovice = 2\n"
    )
    db = init_study(tmp_path_factory.mktemp("outputs"), design, ("novice", "novice"))
    assert main(["run", "--all", "--db", db]) == 0
    return db


@pytest.mark.parametrize(
    "argv",
    [
        ["analyze", "--out", "/proc/no-such-folder"],
        ["figures", "--out", "/proc/no-such-folder"],
        ["analyze", "--out", "{tmp}/a", "--json", "/proc/no-such-file.json"],
        # written through a temporary sibling file (/proc/.no-such-file.csv.XXXX.partial)
        [
            "simulate",
            "--group",
            "novice",
            "--condition",
            "VO",
            "--max-seconds",
            "1",
            "--out",
            "/proc/no-such-file.csv",
        ],
    ],
    ids=["analyze --out", "figures --out", "analyze --json", "simulate --out"],
)
def test_an_output_the_system_will_not_make_is_one_line(
    small_study: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    if not Path("/proc/self").is_dir():
        pytest.skip("no /proc here")
    db = small_study
    args = [a.format(tmp=tmp_path) for a in argv]
    line = _one_line(capsys, [*args, "--db", db] if args[0] != "simulate" else args)
    flag, value = args[-2:]
    assert line.endswith(
        f"{flag} {value}: {value} cannot be written (No such file or directory); expected a "
        "folder or file that can be made and written there"
    ), line


@pytest.mark.parametrize("query", ["mode=ro", "immutable=1", "mode=ro&immutable=1&uri=true"])
def test_init_on_a_read_only_url_of_a_missing_file_makes_no_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], query: str
) -> None:
    from study.protocol.design import TEMPLATE

    (tmp_path / "d.toml").write_text(TEMPLATE)
    db = tmp_path / "new.db"
    argv = ["init", "--design", str(tmp_path / "d.toml"), "--db", f"sqlite:///{db}?{query}"]
    line = _one_line(capsys, argv)
    assert f"no study database at {db}, and the URL opens it read-only" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.toml"]
