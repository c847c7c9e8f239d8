"""Property-based tests over the import and design parsers.

Every generated input is either accepted, and then round-trips (an imported trial comes
back out of `study export` with its values, all within the plausible ranges; a design
survives `to_dict`/`from_dict`), or refused with one line, exit status 2 and no write.
Anything else (a traceback, a second line, a partial write) fails the property.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import shutil
import tempfile
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from sqlalchemy import func, select, table

from db.engine import make_engine
from study.cli import main
from study.errors import StudyInputError
from study.protocol.design import (
    MAX_BREAK_S,
    MAX_GROUP_SIZE,
    MAX_SEED,
    MAX_TRIAL_S,
    MAX_TRIALS_PER_CONDITION,
    TEMPLATE,
    StudyDesign,
    parse_design,
)
from study.protocol.exchange import TRIAL_COLUMNS
from study.tasks.lcca.task import MAX_FORCE_N

JUNK = [
    "",
    " ",
    "inf",
    "-inf",
    "nan",
    "NaN",
    "-1",
    "1e400",
    "1e308",
    "3_0",
    "²",
    "0x10",
    "99999999999999999999999",
    "1e6",
    "=1+1",
    "+1",
    "P1",
    "lcca",
    "HV",
    "true",
    "yes",
    "1.5",
    "180.0001",
    "20.5",
    "\u00a0",
    "é",
]
PEOPLE = [("P001", "novice"), ("P002", "novice"), ("P009", "expert"), ("Q12", "outsider")]
VALID = {
    "task": ["lcca"],
    "condition": ["VO", "HV"],
    "trial": ["1", "2", "3"],
    "completion_time_s": ["0", "12.5", "180", "33.25"],
    "peak_proximal_force_n": ["0", "0.81", "19.99", "1e-3"],
    "peak_distal_force_n": ["0", "0.42", "20"],
    "success": ["true", "false", "1", "0", "no"],
}
JUNK_CELL = st.one_of(st.sampled_from(JUNK), st.text(max_size=5))


@st.composite
def _row(draw: st.DrawFn) -> tuple[str, ...]:
    """A plausible row with none, one or two cells replaced by junk."""
    person = draw(st.sampled_from(PEOPLE))
    row = [*person, *(draw(st.sampled_from(VALID[c])) for c in TRIAL_COLUMNS[2:])]
    for k in draw(st.lists(st.integers(0, len(row) - 1), max_size=2)):
        row[k] = draw(JUNK_CELL)
    return tuple(row)


ROWS = st.lists(_row(), min_size=1, max_size=4)


@pytest.fixture(scope="module")
def template_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("prop")
    (folder / "d.toml").write_text(TEMPLATE)
    db = folder / "s.db"
    assert main(["init", "--design", str(folder / "d.toml"), "--db", str(db)]) == 0
    assert main(["participant", "add", "--group", "novice", "--count", "2", "--db", str(db)]) == 0
    engine = make_engine(f"sqlite:///{db}")
    with engine.connect() as conn:
        conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
    engine.dispose()
    return db


def _run(argv: list[str]) -> tuple[int, list[str]]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(argv)
    return rc, err.getvalue().strip().splitlines()


def _counts(db: Path) -> dict[str, int]:
    engine = make_engine(f"sqlite:///{db}")
    with engine.connect() as conn:
        out = {
            t: conn.scalar(select(func.count()).select_from(table(t)))
            for t in ("participants", "trials", "tlx_responses", "audit_log")
        }
    engine.dispose()
    return out


@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(rows=ROWS)
@example(
    rows=[
        ("P001", "novice", "lcca", "HV", "3", "180", "19.99", "0", "yes"),
        ("Q12", "outsider", "lcca", "VO", "1", "12.5", "1e-3", "20", "0"),
    ]
)
def test_an_import_is_accepted_and_round_trips_or_refused_with_one_line(
    rows: list[tuple[str, ...]], template_db: Path, tmp_path: Path
) -> None:
    work = Path(tempfile.mkdtemp(dir=tmp_path))
    db = work / "s.db"
    shutil.copy(template_db, db)
    path = work / "t.csv"
    with path.open("w", newline="", encoding="utf-8") as f:
        csv.writer(f).writerows([TRIAL_COLUMNS, *rows])
    before = _counts(db)
    rc, err = _run(["import", "--enrol-new", "--trials", str(path), "--db", str(db)])
    if rc == 2:
        assert len(err) == 1, err
        assert err[0].startswith("study import: error: "), err
        assert _counts(db) == before
        return
    assert rc == 0, err
    assert _counts(db)["trials"] == before["trials"] + len(rows)
    rc, err = _run(["export", "--out", str(work / "out"), "--db", str(db)])
    assert rc == 0, err
    exported = pd.read_csv(work / "out" / "trials.csv", dtype={"participant": str})
    for row in rows:
        r = dict(zip(TRIAL_COLUMNS, row, strict=True))
        match = exported[
            (exported.participant == r["participant"].strip())
            & (exported.task == r["task"])
            & (exported.condition == r["condition"])
            & (exported.trial == int(r["trial"]))
        ]
        assert len(match) == 1, (r, exported)
        out = match.iloc[0]
        assert out.group == r["group"]
        for column in ("completion_time_s", "peak_proximal_force_n", "peak_distal_force_n"):
            assert out[column] == pytest.approx(float(r[column]))
        assert 0 <= out.completion_time_s <= MAX_TRIAL_S
        assert 0 <= max(out.peak_proximal_force_n, out.peak_distal_force_n) <= MAX_FORCE_N
        assert bool(out.success) == (r["success"].strip().lower() in ("true", "1", "yes"))


def _toml(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    raise AssertionError(value)


NUMBERS = st.one_of(
    st.integers(-3, 200),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
)
DESIGN_VALUES = {
    "name": st.one_of(st.text(max_size=8), st.text(min_size=199, max_size=205)),
    "seed": NUMBERS,
    "conditions": st.lists(st.sampled_from(["VO", "HV", "XX", ""]), max_size=3),
    "tasks": st.lists(st.sampled_from(["lcca", "notes", "banana"]), max_size=3),
    "trials_per_condition": NUMBERS,
    "practice_trials": NUMBERS,
    "counterbalancing": st.sampled_from(["AB/BA", "latin-square", "none"]),
    "break_s": NUMBERS,
    "code_prefix": st.one_of(
        st.sampled_from(["P", "ABCD", "ÄB", "p", "ABCDE", ""]), st.text(max_size=3)
    ),
}
GROUPS = st.dictionaries(
    st.one_of(
        st.sampled_from(["novice", "expert", "g" * 33]),
        st.from_regex(r"[a-z]{1,6}", fullmatch=True),
    ),
    NUMBERS,
    max_size=3,
)


@settings(max_examples=150, deadline=None)
@given(values=st.fixed_dictionaries({}, optional=DESIGN_VALUES), groups=st.none() | GROUPS)
def test_a_design_is_accepted_within_sane_sizes_or_refused_with_one_line(
    values: dict[str, object], groups: dict[str, object] | None
) -> None:
    text = "".join(f"{k} = {_toml(v)}\n" for k, v in values.items())
    if groups is not None:
        text += "[groups]\n"
        text += "".join(f"{json.dumps(k)} = {_toml(v)}\n" for k, v in groups.items())
    try:
        design = parse_design(text, "d.toml")
    except StudyInputError as exc:
        assert "\n" not in str(exc)
        assert str(exc).startswith("d.toml")
        return
    assert StudyDesign.from_dict(json.loads(json.dumps(design.to_dict()))) == design
    assert 0 <= design.seed <= MAX_SEED
    assert 1 <= design.trials_per_condition <= MAX_TRIALS_PER_CONDITION
    assert math.isfinite(design.break_s)
    assert 0 <= design.break_s <= MAX_BREAK_S
    assert all(1 <= n <= MAX_GROUP_SIZE and len(g) <= 32 for g, n in design.groups.items())
    assert design.code_prefix.isascii()
    assert design.code_prefix.isupper()
