"""The `study` command: help everywhere, and every user error as one line with exit 2."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import click
import pytest

from db.migrate import head_revision
from study.cli import cli, main


def _command_paths(group: click.Group, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    ctx = click.Context(group)
    paths = [prefix]
    for name in group.list_commands(ctx):
        command = group.get_command(ctx, name)
        assert command is not None, f"`study {' '.join((*prefix, name))}` does not load"
        if isinstance(command, click.Group):
            paths += _command_paths(command, (*prefix, name))
        else:
            paths.append((*prefix, name))
    return paths


@pytest.mark.parametrize("path", _command_paths(cli), ids=lambda p: " ".join(p) or "study")
def test_every_command_has_help(path: tuple[str, ...], capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*path, "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"Usage: study {' '.join(path)}".rstrip())


def test_installed_console_script_lists_the_commands() -> None:
    exe = shutil.which("study")
    assert exe is not None, "the `study` console script is not installed"
    result = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0
    for name in ("db", "bench"):
        assert f"  {name} " in result.stdout


_EXIT_PROBE = """
import atexit, gc, sys
import study.cli
class Cycle:
    def __del__(self):
        print("finalised", flush=True)
def report():
    print(f"frozen {gc.get_freeze_count()}", flush=True)
atexit.register(report)
a = Cycle(); a.me = a; del a
sys.argv = ["study", *sys.argv[1:]]
study.cli.entry()
"""


@pytest.mark.parametrize(("args", "status"), [(("--help",), 0), (("no-such-command",), 2)])
def test_console_entry_keeps_status_then_freezes(args: tuple[str, ...], status: int) -> None:
    # the console entry collects the command's garbage (a cycle's finaliser runs) and
    # freezes what remains before the interpreter's exit, keeping main's exit status
    result = subprocess.run(
        [sys.executable, "-c", _EXIT_PROBE, *args], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == status, result.stderr
    lines = result.stdout.splitlines()
    assert "finalised" in lines
    frozen = [int(line.split()[1]) for line in lines if line.startswith("frozen ")]
    assert frozen
    assert frozen[0] > 1000
    assert lines.index("finalised") < lines.index(f"frozen {frozen[0]}")


def _error(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    status = main(list(args))
    captured = capsys.readouterr()
    assert status == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    return lines[0]


def test_unknown_command_names_it(capsys: pytest.CaptureFixture[str]) -> None:
    line = _error(capsys, "frobnicate")
    assert "frobnicate" in line
    assert line.startswith("study: error:")


def test_bad_option_value_names_value_and_expectation(capsys: pytest.CaptureFixture[str]) -> None:
    line = _error(capsys, "bench", "db", "--rows", "lots")
    assert "'lots'" in line
    assert "whole number" in line
    assert line.startswith("study bench db: error:")


def test_missing_option_argument_names_the_command(capsys: pytest.CaptureFixture[str]) -> None:
    line = _error(capsys, "bench", "db", "--rows")
    assert line.startswith("study bench db: error:")
    assert "'--rows' requires an argument" in line


def test_out_of_range_option_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    line = _error(capsys, "bench", "db", "--rows", "0")
    assert "'--rows'" in line
    assert "0" in line


def test_bad_database_url_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    line = _error(capsys, "db", "upgrade", "--db", "mysql://root@localhost/x")
    assert "mysql" in line
    assert "expected sqlite or postgresql" in line


def test_unreachable_server_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    line = _error(capsys, "db", "upgrade", "--db", "postgresql+psycopg://nobody@127.0.0.1:1/x")
    assert line.startswith("study db upgrade: error: cannot open database")
    assert "127.0.0.1:1" in line


def test_foreign_sqlite_file_is_refused_untouched(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "notes.db"
    import sqlite3

    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE notes (body TEXT)")
    before = path.read_bytes()
    line = _error(capsys, "db", "upgrade", "--db", str(path))
    assert "no haptic-study schema revision" in line
    assert path.read_bytes() == before


def test_db_upgrade_creates_then_reports_newest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "study.db"
    assert main(["db", "upgrade", "--db", str(path)]) == 0
    assert f"at revision {head_revision()} (newest)" in capsys.readouterr().out
    assert main(["db", "info", "--db", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["revision"], info["state"]) == (head_revision(), "current")
    assert info["row_counts"]["participants"] == 0


def test_db_option_reads_study_db_from_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "from-env.db"
    monkeypatch.setenv("STUDY_DB", str(path))
    assert main(["db", "upgrade"]) == 0
    assert path.exists()


def test_db_info_on_missing_file_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    line = _error(capsys, "db", "info", "--db", str(tmp_path / "absent.db"))
    assert "absent.db" in line
    assert "expected an existing file" in line


def test_bench_db_writes_its_figures_as_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bench.json"
    assert main(["bench", "db", "--rows", "2500", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    # 2,500 samples at 1 kHz are 2.5 s of trial: three committed chunks.
    assert (result["rows"], result["chunks"], result["backend"]) == (2500, 3, "sqlite")
    assert "rows/s" in capsys.readouterr().out
