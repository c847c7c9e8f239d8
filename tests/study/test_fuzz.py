"""Fuzzing `study` through its entry point, in-process (hypothesis).

- Every command's number options given nan, inf, text, or a value just outside their
  range: one line on stderr, exit status 2, within 10 s, never a traceback.
- The study-data commands (init, enrol, notes, questionnaires, import, export, schedule,
  db info) with random options on a small study: exit 0 or 2 within 10 s, never a
  traceback; after a success the database holds no control character in its text and
  no non-finite number (nonsense accepted would show there).
- Trial CSVs and design TOML files built from valid and nonsense cells: an import or
  init that succeeds stored only plausible values; nonsense is refused.

- Each class of bad input on its own (numbers typed in other scripts' digits or with
  underscores, empty and control-character text, pipes and devices as files, a database
  at an older revision under every command that reads it, notes that look like an
  e-mail address or a phone number): exit 2, one line, no traceback, and the folder's
  files, the database among them, byte for byte as they were.

The CI budget (at least 1,000 cases): 300 + 300 + 250 + 200, and a few dozen per class;
`@pytest.mark.slow` runs more of each, `STUDY_FUZZ_EXAMPLES=2000` sets the examples per
class for a longer run.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import shutil
import signal
import sqlite3
import tempfile
from collections.abc import Iterator
from pathlib import Path

import click
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from study.cli import cli, main
from study.protocol.design import TEMPLATE
from study.protocol.exchange import TRIAL_COLUMNS

HANG_S = 10
FAST = settings(
    deadline=None, suppress_health_check=list(HealthCheck), derandomize=True, database=None
)
"""Deterministic draws (the same cases on every CI run), no example database."""


class Hang(Exception):
    pass


def _alarm(signum: int, frame: object) -> None:
    raise Hang(f"no answer within {HANG_S} s")


def run(argv: list[str], cwd: Path) -> tuple[int, str]:
    """`study ARGV` in `cwd`: its exit status and stderr; a hang past HANG_S raises Hang."""
    err, out = io.StringIO(), io.StringIO()
    old = signal.signal(signal.SIGALRM, _alarm)
    here = Path.cwd()
    signal.alarm(HANG_S)
    try:
        import os

        os.chdir(cwd)
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            code = main(argv)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        os.chdir(here)
    return code, err.getvalue()


def assert_one_line_refusal(code: int, err: str, argv: list[str]) -> None:
    lines = err.strip().splitlines()
    assert code == 2, (argv, code, err)
    assert len(lines) == 1, (argv, err)
    assert ": error: " in lines[0], (argv, err)


def leaf_commands() -> list[tuple[list[str], click.Command]]:
    ctx = click.Context(cli)
    out = []

    def walk(cmd: click.Command, path: list[str]) -> None:
        if isinstance(cmd, click.Group):
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name])
        else:
            out.append((path, cmd))

    walk(cli, [])
    return out


PLACEHOLDER = {
    "design": "d.toml",
    "design_path": "d.toml",
    "campaign_path": "d.toml",
    "trials_csv": "t.csv",
    "group": "novice",
    "code": "P001",
    "text": "a note",
    "reason": "a reason",
    "task": "lcca",
    "condition": "VO",
    "participant": "P001",
}
"""Values for required parameters (by name), so that a refusal is the bad option's."""


def required_args(cmd: click.Command, skip: str) -> list[str]:
    args: list[str] = []
    for p in cmd.params:
        if not p.required or p.name == skip:
            continue
        if isinstance(p.type, click.Choice):
            value = str(p.type.choices[0])
        elif isinstance(p.type, click.types.IntParamType):
            value = "50"
        else:
            value = PLACEHOLDER.get(p.name or "", f"x_{p.name}")
        args += [p.opts[0], value] if isinstance(p, click.Option) else [value]
    return args


def bad_values(p: click.Parameter) -> list[str]:
    """Values of a number option that no command means anything by."""
    t = p.type
    values = ["abc", "1e400x"]
    if isinstance(t, click.types.FloatParamType):
        values += ["nan", "inf", "-inf"]
    if isinstance(t, click.types._NumberRangeBase):
        step = 1 if isinstance(t, click.types.IntParamType) else 1e-9
        if t.min is not None:
            values.append(str(t.min - step if not t.min_open else t.min))
        if t.max is not None:
            values.append(str(t.max + step if not t.max_open else t.max))
    return values


NUMBER_CASES = [
    (path, cmd, p, v)
    for path, cmd in leaf_commands()
    for p in cmd.params
    if isinstance(p, click.Option)
    and isinstance(p.type, click.types.IntParamType | click.types.FloatParamType)
    for v in bad_values(p)
]


@contextlib.contextmanager
def workdir() -> Iterator[Path]:
    with tempfile.TemporaryDirectory() as folder:
        where = Path(folder)
        (where / "d.toml").write_text(TEMPLATE)
        (where / "t.csv").write_text(
            ",".join(TRIAL_COLUMNS) + "\nP001,novice,lcca,VO,1,31.5,0.81,0.42,true\n"
        )
        yield where


def test_every_number_option_is_covered() -> None:
    covered = {(" ".join(path), p.opts[0]) for path, _, p, _ in NUMBER_CASES}
    assert len(covered) >= 40
    assert ("power", "--n-sim") in covered
    assert ("simulate", "--max-seconds") in covered
    assert ("run", "--pace") in covered


@settings(FAST, max_examples=300)
@given(case=st.sampled_from(NUMBER_CASES))
def test_a_bad_number_is_refused_with_one_line(case: tuple) -> None:
    _refused(case)


def _refused(case: tuple) -> None:
    path, cmd, p, value = case
    with workdir() as where:
        argv = [*path, *required_args(cmd, p.name or ""), f"{p.opts[0]}={value}"]
        if "--db" in {o for q in cmd.params for o in q.opts}:
            argv += ["--db", str(where / "s.db")]
        code, err = run(argv, where)
        assert_one_line_refusal(code, err, argv)


# -- the study-data commands with random options ---------------------------------------

TEXT = st.one_of(
    st.sampled_from(
        [
            "P001",
            "P002",
            "P999",
            "P0001",
            "novice",
            "expert",
            "lcca",
            "VO",
            "HV",
            "a note",
            "",
            " ",
            "x" * 600,
            "a\nb",
            "\x1b[2J",
            "caf\u00e9",
            "-1",
        ]
    ),
    st.text(max_size=12),
)
NUMBER = st.one_of(
    st.sampled_from(
        [
            "0",
            "1",
            "3",
            "5",
            "50",
            "100",
            "101",
            "-1",
            "nan",
            "inf",
            "1e308",
            "1e-400",
            "2147483648",
            "99",
            "0.5",
        ]
    ),
    st.integers(-10, 10_000).map(str),
)

CODE = st.sampled_from(["P001", "P002", "P999", "P0001", "p001", "", "P001\n"])
BY_OPTION = {
    "CODE": CODE,
    "--participant": CODE,
    "--group": st.sampled_from(["novice", "expert", "outsider", "surgeon", ""]),
    "--task": st.sampled_from(["lcca", "notes", "x"]),
    "--condition": st.sampled_from(["VO", "HV", "XX"]),
}

LIGHT = {
    "participant add": ["--group", "--site", "--count", "--actor"],
    "participant note": ["CODE", "TEXT", "--actor"],
    "participant withdraw": ["CODE", "--reason", "--actor"],
    "tlx enter": [
        "--participant",
        "--task",
        "--condition",
        "--mental",
        "--physical",
        "--temporal",
        "--performance",
        "--effort",
        "--frustration",
        "--reason",
        "--actor",
    ],
    "tlx show": ["--participant"],
    "tlx pairs": ["--participant"],
    "schedule": [],
    "db info": [],
    "export": ["--out", "--trial", "--participant", "--from-s", "--to-s", "--format"],
    "import": ["--trials", "--actor"],
}
NUMERIC = {
    "--count",
    "--mental",
    "--physical",
    "--temporal",
    "--performance",
    "--effort",
    "--frustration",
    "--trial",
    "--from-s",
    "--to-s",
}


@pytest.fixture(scope="module")
def small_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("fuzz")
    (folder / "d.toml").write_text(TEMPLATE)
    db = str(folder / "s.db")
    assert main(["init", "--design", str(folder / "d.toml"), "--db", db]) == 0
    assert main(["participant", "add", "--group", "novice", "--count", "2", "--db", db]) == 0
    return folder / "s.db"


def stored_nonsense(db: Path) -> list[str]:
    """Text with control characters, and numbers that are not finite, in any table."""
    found = []
    with contextlib.closing(sqlite3.connect(db)) as conn:
        tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        for table in tables:
            if table in ("alembic_version", "sample_chunks"):
                continue
            for row in conn.execute(f'SELECT * FROM "{table}"'):
                for v in row:
                    # the design's TOML text (studies) is the only text with line breaks
                    text = v.replace("\n", " ") if table == "studies" and isinstance(v, str) else v
                    if isinstance(v, str) and not text.isprintable():
                        found.append(f"{table}: {v!r}")
                    if isinstance(v, float) and not math.isfinite(v):
                        found.append(f"{table}: {v!r}")
    return found


@settings(FAST, max_examples=300)
@given(data=st.data())
def test_study_data_commands_with_random_options(small_study: Path, data: st.DataObject) -> None:
    command = data.draw(st.sampled_from(sorted(LIGHT)))
    argv = command.split()
    for option in LIGHT[command]:
        if not data.draw(st.booleans()) and not option.isupper():
            continue
        value = data.draw(NUMBER if option in NUMERIC else BY_OPTION.get(option, TEXT))
        argv += [value] if option.isupper() else [f"{option}={value}"]
    with workdir() as where:
        shutil.copy(small_study, where / "s.db")
        code, err = run([*argv, "--db", str(where / "s.db")], where)
        assert code in (0, 2), (argv, code, err)
        if code == 2:
            assert_one_line_refusal(code, err, argv)
        assert stored_nonsense(where / "s.db") == [], argv


# -- CSV and TOML inputs ---------------------------------------------------------------

CELL = {
    "participant": st.sampled_from(["P001", "P003", "P0003", "p003", "P3", "", "P001 ", "=1+1"]),
    "group": st.sampled_from(["novice", "expert", "outsider", "surgeon", ""]),
    "task": st.sampled_from(["lcca", "notes", "LCCA", ""]),
    "condition": st.sampled_from(["VO", "HV", "XX", ""]),
    "trial": st.sampled_from(["1", "2", "3", "4", "0", "-1", "1.0", "99999999999999999999", "²"]),
    "completion_time_s": NUMBER,
    "peak_proximal_force_n": NUMBER,
    "peak_distal_force_n": NUMBER,
    "success": st.sampled_from(["true", "false", "yes", "maybe", ""]),
}


def _sane_trials(db: Path) -> list[str]:
    bad = []
    with contextlib.closing(sqlite3.connect(db)) as conn:
        for (t,) in conn.execute("SELECT completion_time_s FROM trials WHERE driver='imported'"):
            if t is None or not 0 <= t <= 180:
                bad.append(f"completion time {t!r}")
        for name, v in conn.execute("SELECT name, value FROM trial_measures"):
            if v is None or not 0 <= v <= 20:
                bad.append(f"{name} {v!r}")
        codes = [c for (c,) in conn.execute("SELECT code FROM participants")]
        numbers = [int(c.lstrip("ABCDEFGHIJKLMNOPQRSTUVWXYZ")) for c in codes]
        if len(set(numbers)) != len(numbers):
            bad.append(f"codes {codes}")
        for (pid,) in conn.execute("SELECT id FROM participants"):
            n = conn.execute(
                "SELECT count(*) FROM schedule_blocks WHERE participant_id=?", (pid,)
            ).fetchone()[0]
            if n == 0:
                bad.append(f"participant {pid} without a schedule")
    return bad


@settings(FAST, max_examples=250)
@given(
    rows=st.lists(st.fixed_dictionaries(CELL), min_size=1, max_size=4),
    extra=st.sampled_from(["", "", ",success", ",x", "fields"]),
)
def test_trial_csvs(small_study: Path, rows: list[dict[str, str]], extra: str) -> None:
    header = ",".join(CELL) + ("" if extra == "fields" else extra)
    body = "\n".join(",".join(r.values()).replace("\n", " ") for r in rows)
    if extra:  # every row as long as the header, or (fields) two longer
        body = "\n".join(
            line + (",a,b" if extra == "fields" else ",1") for line in body.split("\n")
        )
    with workdir() as where:
        shutil.copy(small_study, where / "s.db")
        (where / "f.csv").write_text(header + "\n" + body + "\n")
        code, err = run(["import", "--enrol-new", "--trials", "f.csv", "--db", "s.db"], where)
        assert code in (0, 2), (header, body, err)
        if code == 2:
            assert_one_line_refusal(code, err, [header, body])
            want = {
                ",success": "'success' twice",
                "fields": "11 fields; expected 9",
                ",x": "unknown column 'x'",
            }.get(extra)
            assert want is None or want in err, (extra, err)
        else:
            assert extra == "", "a repeated or unknown column was accepted"
            assert _sane_trials(where / "s.db") == [], body
            assert stored_nonsense(where / "s.db") == [], body


TOML_VALUE = st.one_of(
    st.integers(-5, 5000),
    st.sampled_from([float("nan"), float("inf"), -1.5, 0.0, 1e308]),
    st.sampled_from(['"x"', '""', "true", "[]", '["VO", "HV"]', '["lcca"]', '"P"', '"ÄB"']),
)
KEYS = [
    "name",
    "seed",
    "conditions",
    "tasks",
    "trials_per_condition",
    "practice_trials",
    "counterbalancing",
    "break_s",
    "tlx_before_next_block",
    "code_prefix",
    "unknown",
]


def _toml(value: object) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value == math.inf else repr(value))
    return str(value)


@settings(FAST, max_examples=200)
@given(
    top=st.dictionaries(st.sampled_from(KEYS), TOML_VALUE, max_size=4),
    groups=st.dictionaries(
        st.sampled_from(["novice", "expert", "g", " a", "x" * 40]), TOML_VALUE, max_size=4
    ),
)
def test_design_tomls(top: dict[str, object], groups: dict[str, object]) -> None:
    text = "".join(f"{k} = {_toml(v)}\n" for k, v in top.items())
    if groups:
        text += "[groups]\n" + "".join(f'"{k}" = {_toml(v)}\n' for k, v in groups.items())
    with workdir() as where:
        (where / "x.toml").write_text(text)
        code, err = run(["init", "--design", "x.toml", "--db", "n.db"], where)
        assert code in (0, 2), (text, err)
        if code == 2:
            assert_one_line_refusal(code, err, [text])
            assert not (where / "n.db").exists() or stored_nonsense(where / "n.db") == []
            return
        from study.protocol.design import parse_design

        design = parse_design(text)  # what was accepted, read back
        assert text.strip(), "an empty design was accepted"
        assert 1 <= len(design.groups) <= 12
        assert all(1 <= n <= 1000 for n in design.groups.values())
        assert math.isfinite(design.break_s)
        assert 0 <= design.seed
        assert stored_nonsense(where / "n.db") == []


@pytest.mark.slow
@pytest.mark.parametrize("case", NUMBER_CASES, ids=lambda c: " ".join(map(str, c[0])))
def test_every_bad_number_of_every_command(case: tuple) -> None:
    _refused(case)


# -- the classes of bad input, each: exit 2, one line, no traceback, nothing written ----

EXAMPLES = int(os.environ.get("STUDY_FUZZ_EXAMPLES", "0") or 0)
"""Examples per class below: a few dozen in CI; `STUDY_FUZZ_EXAMPLES=2000` for a long run."""


def _examples(ci: int) -> int:
    return EXAMPLES or ci


def _files(where: Path) -> dict[str, bytes]:
    """Every regular file in the folder, by name: what a command could have written."""
    return {p.name: p.read_bytes() for p in sorted(where.iterdir()) if p.is_file()}


def refused_untouched(argv: list[str], where: Path) -> str:
    """`study ARGV` in `where` is refused (exit 2, one line, no traceback) and leaves the
    folder's files (the database among them) byte for byte as they were."""
    before = _files(where)
    code, err = run(argv, where)
    assert "Traceback" not in err, (argv, err)
    assert_one_line_refusal(code, err, argv)
    assert _files(where) == before, (argv, "a refused command wrote")
    return err


@contextlib.contextmanager
def study_copy(small_study: Path) -> Iterator[Path]:
    with workdir() as where:
        shutil.copy(small_study, where / "s.db")
        yield where


# numbers written with what Python's int() takes and a person does not type: other
# scripts' digits (Devanagari, Arabic-Indic, full-width, superscript), underscores,
# signs, spaces inside, hexadecimal
ODD_DIGITS = st.text(
    alphabet=st.characters(categories=["Nd", "No"], exclude_characters="0123456789"),
    min_size=1,
    max_size=3,
)
ODD_NUMBER = st.one_of(
    ODD_DIGITS,
    st.tuples(st.integers(1, 9), st.integers(0, 9)).map(lambda t: f"{t[0]}_{t[1]}"),
    st.integers(1, 99).map(lambda n: f"{n} 0"),
    st.integers(1, 99).map(hex),
    st.tuples(st.integers(1, 9), ODD_DIGITS).map(lambda t: f"{t[0]}{t[1]}"),
)
RATING_OPTIONS = ["--mental", "--physical", "--temporal", "--performance", "--effort"]


@settings(FAST, max_examples=_examples(40))
@given(value=ODD_NUMBER, option=st.sampled_from([*RATING_OPTIONS, "--count"]))
def test_numbers_typed_oddly(small_study: Path, value: str, option: str) -> None:
    with study_copy(small_study) as where:
        if option == "--count":
            argv = ["participant", "add", "--group", "novice", f"--count={value}"]
        else:
            ratings = [f"{o}=50" for o in RATING_OPTIONS if o != option]
            argv = ["tlx", "enter", "--participant", "P001", "--task", "lcca"]
            argv += ["--condition", "VO", "--frustration=50", *ratings, f"{option}={value}"]
        refused_untouched([*argv, "--db", "s.db"], where)


CONTROL = st.characters(categories=["Cc", "Cf", "Zl", "Zp"], exclude_characters="\x00")
BAD_TEXT = st.one_of(
    st.sampled_from(["", " ", "\t", "\u3000"]),
    st.tuples(st.text(max_size=6), CONTROL, st.text(max_size=6)).map("".join),
    st.integers(501, 5000).map(lambda n: "x" * n),
)
TEXT_COMMANDS = [
    (["participant", "note", "P001"], None),
    (["participant", "withdraw", "P001"], "--reason"),
    (["participant", "add", "--group", "novice"], "--site"),
    (["tlx", "show"], "--participant"),
    (["tlx", "pairs"], "--participant"),
    (["export", "--out", "o"], "--participant"),
]


@settings(FAST, max_examples=_examples(40))
@given(text=BAD_TEXT, command=st.sampled_from(TEXT_COMMANDS))
def test_empty_and_control_text(small_study: Path, text: str, command: tuple) -> None:
    argv, option = command
    value = [text] if option is None else [f"{option}={text}"]
    with study_copy(small_study) as where:
        refused_untouched([*argv, *value, "--db", "s.db"], where)
        assert not (where / "o").exists()


@pytest.fixture(scope="module")
def special_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    folder = tmp_path_factory.mktemp("special")
    os.mkfifo(folder / "fifo")
    return {"fifo": str(folder / "fifo"), "zero": "/dev/zero", "null": "/dev/null"}


FILE_COMMANDS = [
    ["import", "--trials", "{f}"],
    ["import", "--trials", "t.csv", "--tlx", "{f}"],
    ["import-xdf", "{f}"],
    ["calibrate", "{f}"],
    ["init", "--design", "{f}", "--db", "n.db"],
    ["db", "info", "--db", "{f}"],
    ["schedule", "--db", "{f}"],
    ["participant", "add", "--group", "novice", "--db", "{f}"],
]


@settings(FAST, max_examples=_examples(24))
@given(command=st.sampled_from(FILE_COMMANDS), kind=st.sampled_from(["fifo", "zero", "null"]))
def test_pipes_and_devices_as_files(
    small_study: Path, special_files: dict[str, str], command: list[str], kind: str
) -> None:
    argv = [a.replace("{f}", special_files[kind]) for a in command]
    if "--db" not in argv and argv[0] != "calibrate":
        argv += ["--db", "s.db"]
    with study_copy(small_study) as where:
        err = refused_untouched(argv, where)
        assert special_files[kind] in err, err  # the file is named


@pytest.fixture(scope="module")
def old_revision(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A database at an older revision, as an earlier `study` left it."""
    from db.engine import make_engine
    from db.migrate import upgrade_schema

    path = tmp_path_factory.mktemp("old") / "s.db"
    engine = make_engine(f"sqlite:///{path}")
    upgrade_schema(engine, "0008_probe_trials")
    engine.dispose()
    return path


READ_COMMANDS = [
    ["schedule"],
    ["tlx", "show"],
    ["tlx", "pairs", "--participant", "P001"],
    ["export", "--out", "o"],
    ["analyze", "--out", "o"],
    ["figures", "--out", "o"],
    ["participant", "add", "--group", "novice"],
    ["run", "--participant", "P001"],
]


@settings(FAST, max_examples=_examples(16))
@given(command=st.sampled_from(READ_COMMANDS))
def test_an_old_revision_is_left_as_it_was(old_revision: Path, command: list[str]) -> None:
    with workdir() as where:
        shutil.copy(old_revision, where / "s.db")
        err = refused_untouched([*command, "--db", "s.db"], where)
        assert "study db upgrade" in err, err
        assert not (where / "o").exists()


PERSONAL = st.one_of(
    # the addresses people write (st.emails() also draws RFC 5322's rarer local parts,
    # such as `{@a.ag`, which the check does not look for)
    st.from_regex(r"[a-z][a-z0-9._]{0,8}@[a-z]{2,8}(\.[a-z]{2,6}){1,2}", fullmatch=True),
    st.tuples(
        st.sampled_from(["+41 ", "+1 (", "0", "(0", ""]),
        st.lists(st.integers(10, 999).map(str), min_size=3, max_size=4),
        st.sampled_from([" ", "-", ".", "/"]),
    ).map(lambda t: t[0] + t[2].join(t[1])),
)
NOTE_COMMANDS = [
    ["participant", "note", "P001"],
    ["participant", "note", "P001", "--session"],
    ["participant", "withdraw", "P001", "--reason"],
]


@settings(FAST, max_examples=_examples(40))
@given(
    contact=PERSONAL,
    before=st.sampled_from(["", "call ", "wrote from ", "reach at: "]),
    command=st.sampled_from(NOTE_COMMANDS),
)
def test_notes_that_look_like_contact_details(
    small_study: Path, contact: str, before: str, command: list[str]
) -> None:
    with study_copy(small_study) as where:
        err = refused_untouched([*command, before + contact, "--db", "s.db"], where)
        assert "--not-personal" in err, err
