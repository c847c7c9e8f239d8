"""Bad input through the real `study` command.

Each case is an input that gave a traceback or was accepted as nonsense. Through
`study.cli.main`, as the console script runs it, each must now end with exactly one
line on stderr naming the value and what was expected, exit status 2, and nothing
written: the database's row counts and the folder's files are the same afterwards.
"""

from __future__ import annotations

import random
import shutil
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from sqlalchemy import func, inspect, select, table

from db.engine import make_engine
from study.cli import main
from study.protocol.design import TEMPLATE
from study.protocol.exchange import TLX_COLUMNS, TLX_WEIGHT_COLUMNS, TRIAL_COLUMNS

TRIAL_ROW = "P001,novice,lcca,VO,1,31.5,0.81,0.42,true"
TLX_ROW = "P001,lcca,VO,70,20,50,30,60,40,5,0,3,2,4,1"


def trials(*rows: str) -> bytes:
    return (",".join(TRIAL_COLUMNS) + "\n" + "\n".join(rows) + "\n").encode()


def tlx(*rows: str) -> bytes:
    return (",".join(TLX_COLUMNS + TLX_WEIGHT_COLUMNS) + "\n" + "\n".join(rows) + "\n").encode()


def design(**values: str) -> bytes:
    """The template with `key = value` lines replaced or added (values as TOML text;
    `groups.NAME` for a group)."""
    lines, in_groups = [], False
    for line in TEMPLATE.splitlines():
        in_groups = in_groups or line.startswith("[groups]")
        key = ("groups." if in_groups else "") + line.split("=")[0].strip()
        if key in values:
            line = f"{key.removeprefix('groups.')} = {values.pop(key)}"
        lines.append(line)
    top = [f"{k} = {v}" for k, v in values.items() if not k.startswith("groups.")]
    groups = [
        f"{k.removeprefix('groups.')} = {v}" for k, v in values.items() if k.startswith("groups.")
    ]
    at = next(i for i, line in enumerate(lines) if line.startswith("[groups]"))
    return "\n".join(lines[:at] + top + lines[at:] + groups).encode()


@dataclass
class Case:
    id: str
    argv: list[str]
    expect: str
    """A piece of the one line: the bad value, and what was expected."""
    files: dict[str, bytes] = field(default_factory=dict)
    before: list[list[str]] = field(default_factory=list)
    """Commands that must succeed first (the state the bad input meets)."""
    env: dict[str, str] = field(default_factory=dict)


def imp(csv: bytes, expect: str, id: str, before: list[list[str]] | None = None) -> Case:
    return Case(id, ["import", "--trials", "t.csv"], expect, {"t.csv": csv}, before or [])


def imp_tlx(tlx_row: str, expect: str, id: str) -> Case:
    """`study import` of a good trial and a questionnaire row with one bad value."""
    return Case(
        id,
        ["import", "--trials", "t.csv", "--tlx", "x.csv"],
        expect,
        {"t.csv": trials(TRIAL_ROW), "x.csv": tlx(tlx_row)},
    )


def init(toml: bytes, expect: str, id: str) -> Case:
    return Case(id, ["init", "--design", "d2.toml", "--db", "new.db"], expect, {"d2.toml": toml})


ENTER = [
    "tlx",
    "enter",
    "--participant",
    "P001",
    "--task",
    "lcca",
    "--condition",
    "VO",
    "--mental=70",
    "--physical=20",
    "--temporal=50",
    "--performance=30",
    "--effort=60",
    "--frustration=40",
]
ENTER_UNRUN = [*ENTER, "--reason", "paper form, block not run"]
SIMULATE = ["simulate", "--group", "novice", "--condition", "HV", "--out", "sim.csv"]
POWER = ["power", "--design", "d.toml", "--n-sim", "10"]
"""ENTER for a block with no trial yet: that needs a reason too."""

CASES = [
    # 5: tracebacks
    imp(
        trials(TRIAL_ROW),
        "P001 lcca/VO trial 1 is already stored",
        "same file twice",
        before=[["import", "--trials", "t.csv"]],
    ),
    Case(
        "tlx for a block that has one",
        ["import", "--trials", "t.csv", "--tlx", "x.csv"],
        "P001/lcca/VO already has a questionnaire",
        {"t.csv": trials("P001,novice,lcca,HV,1,31.5,0.81,0.42,true"), "x.csv": tlx(TLX_ROW)},
        [ENTER_UNRUN],
    ),
    imp(b"", "t.csv is empty", "empty csv"),
    imp(trials(), "t.csv has a header but no rows", "header only"),
    imp_tlx(
        TLX_ROW.replace(",70,", ",inf,"),
        "column mental: 'inf' is not a plain decimal",
        "rating inf",
    ),
    imp_tlx(
        TLX_ROW.replace(",70,", ",1e400,"), "mental rating inf is off the scale", "rating 1e400"
    ),
    imp_tlx(
        TLX_ROW.replace(",5,0,", ",1e400,0,"),
        "mental weight inf; expected a whole number of choices 0-5",
        "weight 1e400",
    ),
    imp(
        trials(TRIAL_ROW.replace(",1,31.5", ",²,31.5")),
        "'²'; expected a whole number from 1 to 3",
        "trial superscript two",
    ),
    imp(
        trials(TRIAL_ROW.replace(",1,31.5", ",99999999999999999999999,31.5")),
        "expected a whole number from 1 to 3",
        "trial 1e23",
    ),
    init(b'name = "caf\xe9"\n', "not UTF-8 text (byte 0xe9 at offset 11)", "non-utf8 design"),
    init(design(seed="-1"), "seed = -1; expected 0 to 2147483647", "seed -1"),
    init(design(seed=str(2**70)), f"seed = {2**70}; expected 0 to 2147483647", "seed 2**70"),
    init(
        design(trials_per_condition=str(2**63)),
        "trials_per_condition = 9223372036854775808; expected 1 to 100",
        "trials 2**63",
    ),
    Case("corrupted database", ["schedule", "--db", "bad.db"], "bad.db", {}),
    Case(
        "corrupted database, add",
        ["participant", "add", "--group", "novice", "--db", "bad.db"],
        "bad.db",
    ),
    Case("corrupted database, run", ["run", "--participant", "P001", "--db", "bad.db"], "bad.db"),
    Case("corrupted database, export", ["export", "--out", "out", "--db", "bad.db"], "bad.db"),
    Case(
        "unparsable postgres url",
        ["schedule", "--db", "postgresql+psycopg://::::"],
        "'postgresql+psycopg://::::' is not a URL; expected",
    ),
    Case(
        "site over 64",
        ["participant", "add", "--group", "novice", "--site", "s" * 65],
        "expected 1-64 printable characters",
    ),
    init(
        design(**{"groups." + "g" * 33: "2"}), "expected 1-32 printable characters", "group over 32"
    ),
    init(design(break_s="nan"), "break_s = nan; expected 0 to 3600 s", "break nan"),
    # 6: nonsense that was accepted
    imp(
        trials(TRIAL_ROW.replace("31.5", "1e308")),
        "column completion_time_s: '1e308' is out of range; expected a number from 0 to 180",
        "time 1e308",
    ),
    imp(
        trials(TRIAL_ROW.replace("0.81", "1e6")),
        "column peak_proximal_force_n: '1e6' is out of range; expected a number from 0 to 20",
        "force 1e6 N",
    ),
    imp(
        trials(TRIAL_ROW.replace(",1,31.5", ",1000000,31.5")),
        "'1000000'; expected a whole number from 1 to 3",
        "trial 1000000",
    ),
    imp(trials(TRIAL_ROW.replace("31.5", "3_0")), "'3_0' is not a plain decimal", "3_0"),
    init(
        design(**{"groups.novice": str(10**12)}),
        "expected a whole number from 1 to 1000",
        "group 1e12",
    ),
    init(design(trials_per_condition="1000000000"), "expected 1 to 100", "1e9 trials"),
    init(design(break_s="inf"), "break_s = inf; expected 0 to 3600 s", "break inf"),
    init(
        design(code_prefix='"ÄB"'),
        "code_prefix = 'ÄB'; expected 1-4 capital letters A-Z",
        "code prefix",
    ),
    Case(
        "pace nan",
        ["run", "--participant", "P001", "--pace", "nan"],
        "--pace nan; expected a finite number 0.01<=x<=1000",
    ),
    Case("pace inf", ["run", "--all", "--pace", "inf"], "inf is not in the range 0.01<=x<=1000"),
    imp_tlx(
        TLX_ROW.replace("lcca,VO", "banana,VO"),
        "column task: 'banana'; expected one of lcca",
        "tlx task banana",
    ),
    imp_tlx(
        TLX_ROW.replace("lcca,VO", "lcca,XX"),
        "column condition: 'XX'; expected one of VO, HV",
        "tlx condition XX",
    ),
    # 8: a bad --port leaves no trial behind
    Case(
        "bad port",
        ["run", "--participant", "P001", "--driver", "hardware", "--port", "/dev/no-such-port"],
        "--port /dev/no-such-port: cannot open",
    ),
    # 9: an edit needs a reason
    Case(
        "tlx edit without reason",
        [*ENTER[:12], "--effort=65", *ENTER[13:]],
        "needs a reason",
        before=[ENTER_UNRUN],
    ),
    Case("tlx for a block not run, no reason", ENTER, "has no completed trial yet"),
    Case("actor too long", [*ENTER, "--actor", "a" * 65], "--actor 'aaaa"),
    # what independent checks found: tracebacks
    Case(
        "max-seconds nan",
        [*SIMULATE, "--max-seconds", "nan"],
        "--max-seconds nan; expected a finite number 1<=x<=3600",
    ),
    Case("seed -1", [*SIMULATE, "--seed", "-1"], "-1 is not in the range 0<=x<=4294967295"),
    Case(
        "pace 1e-300",
        ["run", "--participant", "P001", "--pace", "1e-300"],
        "1e-300 is not in the range 0.01<=x<=1000",
    ),
    # unbounded
    Case(
        "count 1e9",
        ["participant", "add", "--group", "novice", "--count", "1000000000"],
        "--count 1000000000 for group novice, which has 2 of its 8 enrolled; expected at most 6",
    ),
    Case(
        "count past the target",
        ["participant", "add", "--group", "novice", "--count", "7"],
        "--count 7 for group novice, which has 2 of its 8 enrolled; expected at most 6",
    ),
    Case(
        "n-sim 1e12",
        [*POWER, "--n-sim", "1000000000000"],
        "1000000000000 is not in the range 10<=x<=100000",
        {"d.toml": TEMPLATE.encode()},
    ),
    # accepted nonsense
    *[
        Case(
            f"effect {v}",
            [*POWER, "--effect", v],
            f"--effect '{v}': outsider",
            {"d.toml": TEMPLATE.encode()},
        )
        for v in ("nan", "inf", "-inf", "1e308")
    ],
    Case(
        "effect per group nan",
        [*POWER, "--effect", "outsider=1,novice=nan,expert=1"],
        "novice nan; expected a finite standardised effect from -10 to 10",
        {"d.toml": TEMPLATE.encode()},
    ),
    Case(
        "haptic gain 1e9",
        [*SIMULATE, "--haptic-gain", "1e9"],
        "haptic gain 1000000000.0; expected 0 to 1 N m/N",
    ),
    Case(
        "tlx show unknown", ["tlx", "show", "--participant", "P999"], "unknown participant 'P999'"
    ),
    Case(
        "note with control characters",
        ["participant", "note", "P001", "a\nb\x1b[2J"],
        "holds control characters; expected printable text on one line",
    ),
    Case(
        "session note with a tab",
        ["participant", "note", "P001", "a\tb", "--session"],
        "holds control characters",
    ),
    Case(
        "jobs with participant",
        ["run", "--participant", "P001", "--jobs", "2"],
        "--jobs 2 with --participant; expected --all",
    ),
    Case(
        "samples of trial 99",
        ["export", "--out", "o", "--samples", "--trial", "99"],
        "--trial 99; expected 1 to 3",
    ),
    imp(
        trials(TRIAL_ROW.replace("0.81", "1e-400")),
        "column peak_proximal_force_n: '1e-400' is too small to store",
        "force 1e-400",
    ),
    *[
        Case(f"db url {q}", ["db", "info", "--db", f"sqlite:///s.db?{q}"], want)
        for q, want in (
            ("timeout=abc", "timeout='abc'; expected seconds"),
            ("timeout=-1", "timeout='-1'; expected seconds"),
            ("timeout=nan", "timeout='nan'; expected seconds"),
            ("foo=bar", "has parameter 'foo'; expected only timeout, mode, immutable, uri"),
        )
    ],
    init(b"", "d2.toml is empty; expected a study design", "empty design"),
    init(b"# only a comment\n", "d2.toml is empty; expected a study design", "comment design"),
    init(
        design(**{f"groups.g{i}": "1" for i in range(13)}),
        "[groups] has 16 groups; expected 1 to 12",
        "16 groups",
    ),
    imp(
        trials(TRIAL_ROW.replace("P001", "P0001")),
        "'P0001' beside 'P001', the same number written with other zeros; expected P001",
        "P0001 beside P001",
    ),
    imp(
        trials(
            TRIAL_ROW.replace("P001", "P0003"),
            TRIAL_ROW.replace("P001", "P003").replace(",1,31.5", ",2,31.5"),
        ),
        "row 3, column participant: 'P003' beside 'P0003'",
        "P0003 and P003 in one file",
    ),
    # misleading messages
    Case(
        "duplicate column",
        ["import", "--trials", "t.csv"],
        "has column 'success' twice",
        {"t.csv": (",".join(TRIAL_COLUMNS) + ",success\n" + TRIAL_ROW + ",true\n").encode()},
    ),
    imp(trials(TRIAL_ROW + ",VO,a,b"), "t.csv row 2: 12 fields; expected 9", "extra fields"),
]


def _state(folder: Path, db: str) -> tuple[dict[str, int], list[str]]:
    engine = make_engine(f"sqlite:///{db}")
    try:
        with engine.connect() as conn:
            counts = {
                t: conn.scalar(select(func.count()).select_from(table(t)))
                for t in inspect(conn).get_table_names()
            }
    finally:
        engine.dispose()
    files = sorted(
        str(p.relative_to(folder))
        for p in folder.rglob("*")
        if not p.name.endswith(("-wal", "-shm"))
    )
    return counts, files


def _corrupt(db: Path, target: Path) -> None:
    """A copy of `db` with the pages of its study tables overwritten: it opens, and its
    schema revision reads, but a command's first query of the data fails."""
    shutil.copy(db, target)
    with sqlite3.connect(target) as conn:
        page_size = conn.execute("PRAGMA page_size").fetchone()[0]
        pages = [
            r[0]
            for r in conn.execute(
                "SELECT rootpage FROM sqlite_master WHERE tbl_name IN "
                "('studies', 'participants', 'schedule_blocks', 'trials', 'session_leases')"
            )
        ]
    conn.close()
    data = bytearray(target.read_bytes())
    rng = random.Random(18)
    for page in pages:
        start = (page - 1) * page_size
        data[start : start + page_size] = rng.randbytes(page_size)
    target.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def study_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("study")
    (folder / "d.toml").write_text(TEMPLATE)
    db = str(folder / "s.db")
    assert main(["init", "--design", str(folder / "d.toml"), "--db", db]) == 0
    assert main(["participant", "add", "--group", "novice", "--count", "2", "--db", db]) == 0
    # one checkpointed file, so that a copy is the whole database
    engine = make_engine(f"sqlite:///{db}")
    with engine.connect() as conn:
        conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
    engine.dispose()
    return folder / "s.db"


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_one_line_exit_2_and_nothing_written(
    case: Case,
    study_db: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    shutil.copy(study_db, tmp_path / "s.db")
    _corrupt(study_db, tmp_path / "bad.db")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("STUDY_DB", "s.db")
    for name, content in case.files.items():
        (tmp_path / name).write_bytes(content)
    for argv in case.before:
        assert main(argv) == 0, capsys.readouterr().err
    before = _state(tmp_path, "s.db")
    bad_bytes = (tmp_path / "bad.db").read_bytes()
    capsys.readouterr()
    assert main(case.argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("study "), err
    assert ": error: " in err[0], err
    assert case.expect in err[0], err
    assert _state(tmp_path, "s.db") == before
    assert (tmp_path / "bad.db").read_bytes() == bad_bytes


@pytest.mark.postgres
@pytest.mark.parametrize(
    "argv, expect",
    [
        (["participant", "add", "--group", "novice", "--site", "s" * 65], "expected 1-64"),
        (["import", "--trials", "t.csv"], "'1e6' is out of range"),
    ],
)
def test_on_postgresql_too(
    pg_url: str,
    tmp_path: Path,
    argv: list[str],
    expect: str,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "d.toml").write_text(TEMPLATE)
    (tmp_path / "t.csv").write_bytes(trials(TRIAL_ROW.replace("0.81", "1e6")))
    assert main(["init", "--design", "d.toml", "--db", pg_url]) == 0
    capsys.readouterr()
    assert main([*argv, "--db", pg_url]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert expect in err[0], err
    engine = make_engine(pg_url)
    with engine.connect() as conn:
        assert conn.scalar(select(func.count()).select_from(table("participants"))) == 0
        assert conn.scalar(select(func.count()).select_from(table("trials"))) == 0
    engine.dispose()
