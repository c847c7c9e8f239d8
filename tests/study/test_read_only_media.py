"""A study database on read-only media can be inspected: `db info`, `db check`,
`schedule`, `tlx show`, `export` and `analyze` (to a writable folder) work on a file
`chmod 0444` in a folder `chmod 0555`, through SQLite's read-only, immutable open, and
leave the file and its folder exactly as they were (no journal, WAL or lock file); a
command that writes is refused with one line saying the database is read-only.

Root ignores file permissions: as root the commands run as the unprivileged user nobody
(`setpriv`, util-linux), all in one interpreter to keep the test fast. The same commands
are also run here, in-process, on the read-only immutable URL itself (what the command
line opens such a file with, and what `--db` may give), which holds whoever runs the
tests; written as a path, `?mode=ro&uri=true` once made pysqlite create an empty database
named `study.db?mode=ro` beside the study."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from study.cli import main
from tests.study.conftest import init_study

NOBODY = 65534
DESIGN = """\
name = "read-only media"
tasks = ["lcca"]
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 2
expert = 2
"""
READING = [
    ["db", "info"],
    ["db", "check"],
    ["schedule"],
    ["tlx", "show"],
    ["export", "--out", "{out}/export"],
    ["analyze", "--out", "{out}/analysis"],
]
WRITING = [
    ["participant", "note", "P001", "wore glasses"],
    ["participant", "add", "--group", "novice", "--beyond-target"],
]


@pytest.fixture(scope="module")
def study_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("ro-study")
    db = init_study(folder, DESIGN, ("novice", "novice", "expert", "expert"))
    assert main(["run", "--all", "--db", db]) == 0
    with contextlib.closing(sqlite3.connect(db)) as conn:  # the log folded into the file,
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")  # as media are written
    return Path(db)


@pytest.fixture
def media(study_file: Path) -> Iterator[tuple[Path, Path]]:
    """(database, writable output folder): the study copied into a folder of mode 0555 as
    a file of mode 0444, as on a write-protected card or a read-only mount."""
    base = Path(tempfile.mkdtemp(prefix="study-media-"))
    os.chmod(base, 0o755)  # others may enter (mkdtemp makes it 0700)
    folder, out = base / "media", base / "out"
    folder.mkdir()
    out.mkdir()
    os.chmod(out, 0o777)
    db = folder / "study.db"
    shutil.copy(study_file, db)
    os.chmod(db, 0o444)
    os.chmod(folder, 0o555)
    try:
        yield db, out
    finally:
        os.chmod(folder, 0o755)
        shutil.rmtree(base, ignore_errors=True)


def _unchanged(db: Path, before: bytes) -> None:
    assert db.read_bytes() == before
    assert sorted(p.name for p in db.parent.iterdir()) == [db.name]


RUNNER = """
import contextlib, io, json, sys
from study.cli import main
results = []
for argv in json.loads(sys.argv[1]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(argv)
    results.append([code, err.getvalue()])
print(json.dumps(results))
"""


def _as_unprivileged(commands: list[list[str]], where: Path) -> list[tuple[int, str]]:
    """Each command's exit status and stderr, run in one interpreter: as nobody when this
    is root (else as this user, whom the permissions already hold)."""
    prefix: list[str] = []
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.skip("running as root without setpriv: a read-only file is writable to root")
        prefix = [setpriv, f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups"]
    env = {
        **os.environ,
        "HOME": str(where),
        "MPLCONFIGDIR": str(where / "mpl"),
        "PYTHONPATH": str(Path(__file__).resolve().parents[2]),
    }
    env.pop("STUDY_DB", None)
    done = subprocess.run(
        [*prefix, sys.executable, "-c", RUNNER, json.dumps(commands)],
        capture_output=True,
        text=True,
        env=env,
        cwd=where,
        timeout=120,
        check=False,
    )
    if prefix and done.returncode != 0 and "Permission denied" in done.stderr:
        pytest.skip("nobody cannot read the checkout or the interpreter here")
    assert done.returncode == 0, done.stderr
    return [(code, err) for code, err in json.loads(done.stdout.strip().splitlines()[-1])]


def test_a_read_only_file_in_a_read_only_folder_can_be_inspected(
    media: tuple[Path, Path],
) -> None:
    db, out = media
    before = db.read_bytes()
    reading = [[a.format(out=out) for a in argv] + ["--db", str(db)] for argv in READING]
    writing = [[*argv, "--db", str(db)] for argv in WRITING]
    results = _as_unprivileged([*reading, *writing], out)
    for argv, (code, err) in zip(reading, results[: len(reading)], strict=True):
        assert code == 0, (argv, err)
        assert "Traceback" not in err, (argv, err)
    assert (out / "export" / "trials.csv").is_file()
    assert (out / "analysis" / "analysis.json").is_file()
    for argv, (code, err) in zip(writing, results[len(reading) :], strict=True):
        lines = err.strip().splitlines()
        assert code == 2, (argv, err)
        assert len(lines) == 1, (argv, err)
        assert "is read-only" in lines[0], lines[0]
        assert "expected a writable database" in lines[0], lines[0]
    _unchanged(db, before)


URLS = [
    "sqlite:///file:{db}?mode=ro&immutable=1&uri=true",  # SQLite's URI filename
    "sqlite:///{db}?mode=ro&immutable=1&uri=true",  # a path: made a URI filename
    "sqlite:///{db}?immutable=1",  # uri=true implied
]


@pytest.mark.parametrize("form", URLS)
def test_the_read_only_immutable_url_reads_and_refuses_writes_in_one_line(
    media: tuple[Path, Path], capsys: pytest.CaptureFixture[str], form: str
) -> None:
    db, out = media
    before = db.read_bytes()
    url = form.format(db=db)
    for argv in READING:
        args = [a.format(out=out) for a in argv]
        assert main([*args, "--db", url]) == 0, (args, capsys.readouterr().err)
    capsys.readouterr()
    assert (out / "export" / "trials.csv").is_file()
    for argv in WRITING:
        assert main([*argv, "--db", url]) == 2, argv
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1, lines
        assert "is read-only" in lines[0], lines[0]
    _unchanged(db, before)
