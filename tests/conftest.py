"""Shared fixtures: a study database on each backend.

`db_url` runs a test on SQLite (a file in the test's temporary folder) and on
PostgreSQL (a private schema on the server named by STUDY_TEST_PG_URL, dropped
afterwards). PostgreSQL cases skip only when that variable is unset; a server that is
set but unreachable fails them. The run ends with a line saying how many PostgreSQL
cases ran, so CI's log shows they were not skipped.
"""

from __future__ import annotations

import os
import sqlite3
import sys
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path

import pyarrow as pa
import pytest
from sqlalchemy import Engine, text
from sqlalchemy.engine import make_url

from db.engine import make_engine
from db.migrate import open_database
from study.lsl.config import ENV as LSL_ENV
from study.lsl.config import write_loopback_config

PG_ENV = "STUDY_TEST_PG_URL"

# pytest-xdist runs one worker per core: a worker's OpenMP pool (scikit-learn's
# gradient boosting, PyTorch) of one thread per core as well would put cores x cores
# spinning threads on the machine, and under other load the boosting's split loop
# slowed by a factor of tens (a quick bench hit the 300 s timeout). Read by the OpenMP
# runtimes when they start, so it is set before any test imports them.
os.environ.setdefault("OMP_NUM_THREADS", "1")

# The Lab Streaming Layer only ever on loopback here: liblsl reads its configuration once,
# when pylsl first loads, from the file LSLAPICFG names; it is set before any test can
# import pylsl (and is inherited by the commands the tests start). Its own session id
# keeps one test process's streams apart from another's. tests/study/lsl checks it.
LSL_CONFIG = write_loopback_config(
    Path(tempfile.mkdtemp(prefix="lsl-loopback-")) / "lsl_api.cfg", f"tests-{uuid.uuid4().hex}"
)
os.environ[LSL_ENV] = str(LSL_CONFIG)
PYLSL_LOADED_BEFORE_CONFIG = "pylsl" in sys.modules
"""Whether pylsl was already loaded when the config was set (it must not be)."""


def decode_stored_chunk(data: bytes, raw_bytes: int, schema_data: bytes) -> pa.RecordBatch:
    """A `sample_chunks.data` value decoded with plain pyarrow, as the format's
    description says (independently of `db.sample_reader`): in the schema stored as
    `schema_data` (`sample_schemas.data`)."""
    message = pa.decompress(bytes(data), decompressed_size=raw_bytes, codec="zstd")
    schema = pa.ipc.read_schema(pa.py_buffer(bytes(schema_data)))
    return pa.ipc.read_record_batch(message, schema)


CHUNKS_SQL = (
    "SELECT c.trial_id, c.first_seq, c.raw_bytes, c.data, s.data FROM sample_chunks c "
    "JOIN sample_schemas s ON s.id = c.schema_id"
)


def expose_samples(conn: sqlite3.Connection) -> None:
    """Every stored sample of the SQLite study database behind `conn`, decoded from its
    chunks (each in its stored schema), as a temporary table `samples` (trial_id, seq,
    every column of every stored schema), so that a check can be written as one SQL
    query."""
    chunks = conn.execute(CHUNKS_SQL).fetchall()
    decoded = [(t, first, decode_stored_chunk(d, raw, s)) for t, first, raw, d, s in chunks]
    names = list(dict.fromkeys(n for *_, batch in decoded for n in batch.schema.names))
    conn.execute(f"CREATE TEMP TABLE samples (trial_id, seq, {', '.join(names)})")
    for trial_id, first_seq, batch in decoded:
        columns = batch.to_pydict()
        n = batch.num_rows
        rows = zip([trial_id] * n, range(first_seq, first_seq + n), *columns.values(), strict=True)
        conn.executemany(
            f"INSERT INTO samples (trial_id, seq, {', '.join(columns)}) "
            f"VALUES ({', '.join('?' * (len(columns) + 2))})",
            rows,
        )


def pg_schema_url(base: str, schema: str) -> str:
    """`base` with every connection's search_path set to `schema`."""
    url = make_url(base).update_query_dict({"options": f"-csearch_path={schema}"})
    return url.render_as_string(hide_password=False)


@pytest.fixture
def pg_url() -> Iterator[str]:
    """URL of a fresh, empty schema on the test PostgreSQL server."""
    base = os.environ.get(PG_ENV)
    if not base:
        pytest.skip(f"{PG_ENV} is not set")
    schema = f"t_{uuid.uuid4().hex[:16]}"
    admin = make_engine(base)
    with admin.begin() as conn:
        conn.execute(text(f'CREATE SCHEMA "{schema}"'))
    try:
        yield pg_schema_url(base, schema)
    finally:
        with admin.begin() as conn:
            conn.execute(text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


@pytest.fixture
def sqlite_url(tmp_path) -> str:  # type: ignore[no-untyped-def]
    return f"sqlite:///{tmp_path / 'study.db'}"


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def db_url(request: pytest.FixtureRequest) -> str:
    """An empty database on each backend (no schema yet)."""
    name = "sqlite_url" if request.param == "sqlite" else "pg_url"
    return request.getfixturevalue(name)


@pytest.fixture
def engine(db_url: str) -> Iterator[Engine]:
    """A study database at the newest schema, on each backend."""
    eng = open_database(db_url)
    try:
        yield eng
    finally:
        eng.dispose()


_pg_outcomes: dict[str, int] = {}


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if "postgres" in report.keywords and (report.when == "call" or report.skipped):
        _pg_outcomes[report.outcome] = _pg_outcomes.get(report.outcome, 0) + 1


def pytest_terminal_summary(terminalreporter) -> None:  # type: ignore[no-untyped-def]
    if _pg_outcomes:
        parts = ", ".join(f"{n} {outcome}" for outcome, n in sorted(_pg_outcomes.items()))
        where = os.environ.get(PG_ENV) or f"{PG_ENV} unset"
        terminalreporter.write_line(f"PostgreSQL cases ({where}): {parts}")


SLOW_MODULES = frozenset(
    {
        # train a GRU, calibrate, or compile the loop
        "tests/teleop_core/test_firmware.py",  # builds the firmware's host build
        "tests/study/test_hardware_session.py",  # the same, and sessions in real time
        "tests/study/test_hardware_drive_session.py",  # the same, with a drive unit too
        "tests/study/lsl/test_lsl_forces.py",  # the same, forces from an LSL stream
        "tests/teleop_core/test_follower_units.py",  # builds the firmware's host build
        "tests/study/test_stopped_sessions.py",  # sessions in real time, signalled
        "tests/teleop_core/test_gru.py",
        "tests/teleop_core/test_estimator.py",
        "tests/teleop_core/test_calibration.py",
        "tests/teleop_core/test_generalisation.py",
        "tests/teleop_core/test_cold_start.py",
        "tests/teleop_core/test_memory.py",
        "tests/teleop_core/test_regimes.py",
        "tests/teleop_core/test_scenarios.py",
        "tests/teleop_core/notes/test_identify.py",
        "tests/teleop_core/test_rigid_axis.py",
        "tests/teleop_core/test_extended_physics.py",
        "tests/teleop_core/test_loop.py",
        "tests/teleop_core/test_hardware.py",
        "tests/study/test_estimator_cli.py",
        "tests/study/test_estimator_residual_cli.py",
        "tests/study/test_estimator_effects_cli.py",
        "tests/study/test_estimator_calibration_cli.py",
        "tests/study/test_calibrate_cli.py",
        "tests/study/test_calibrate_validate_cli.py",
        "tests/study/test_calibration_figures.py",
        # whole simulated studies, sessions, campaigns, benches and the participant fit
        "tests/study/test_campaign.py",
        "tests/study/test_kill_points.py",
        "tests/study/test_participants.py",
        "tests/study/test_participant_fit.py",
        "tests/study/test_participant_effects_closed_form.py",
        "tests/study/test_participant_effects_one_measure.py",
        "tests/study/test_participant_fit_effects.py",
        "tests/study/test_participant_fit_one_measure.py",
        "tests/study/test_participant_fit_notes.py",
        "tests/study/test_participant_fit_samples.py",
        "tests/study/test_participant_fit_validate.py",
        "tests/study/test_simulation_workers.py",
        "tests/study/test_probes_fit.py",
        "tests/study/test_figures_demo.py",
        "tests/study/test_figures.py",
        "tests/study/test_notes_surgeons.py",
        "tests/study/test_haptic_gain.py",
        "tests/study/test_session.py",
        "tests/study/test_multisite.py",
        "tests/study/test_bench_export.py",
        "tests/study/test_bench_master_cli.py",
        "tests/study/test_bench_startup_cli.py",
        "tests/study/test_sample_export_spans.py",
        "tests/study/test_properties.py",
        "tests/study/test_recording_properties.py",
        # the terminal app driven by its pilot or in a real terminal, and import-linter
        "tests/study/tui/test_lab_day.py",
        "tests/study/tui/test_lab_day_terminal.py",
        "tests/study/tui/test_run_session.py",
        "tests/study/tui/test_adding_a_task.py",
        "tests/study/tui/test_snapshots.py",
        "tests/study/tui/test_terminal.py",
        "tests/study/tui/test_terminal_db_errors.py",
        "tests/study/tui/test_db_errors.py",
        "tests/study/tui/test_screens.py",
        "tests/study/tui/test_participant_page.py",
        "tests/study/tui/test_terminal_keys.py",
        "tests/study/tui/test_terminal_screens.py",
        "tests/study/tui/test_terminal_read_only.py",
        "tests/study/tui/test_ops_keys.py",
        "tests/study/tui/test_break_bell.py",
        "tests/study/tui/test_run_choices.py",
        "tests/study/tui/test_tlx_drafts.py",
        "tests/study/tui/test_trial_lock.py",
        "tests/study/test_lease.py",
        "tests/test_layering.py",
        "tests/study/test_layers.py",
    }
)
"""Test modules marked `slow`: the fast lane, `pytest -m "not slow"`, leaves them out
(README). A module belongs here when its tests train, calibrate, compile, drive the
terminal app or simulate whole studies; the full suite runs everything."""
SLOW_TESTS = (
    "tests/study/test_sample_export.py::test_export_memory_does_not_grow_with_the_samples",
    "tests/study/test_analysis.py::test_study_analyze_",
    "tests/study/test_export_roundtrip.py::test_an_export_imports_back_",
    "tests/study/test_participant_fit_coverage.py::test_the_intervals_of_a_fit_whose_model_holds_",
    "tests/study/test_probes.py::test_probe_run_stores_export_import_and_covariate",
    "tests/study/test_fuzz.py::test_trial_csvs",
    "tests/study/test_simulate_cli.py::test_simulate_writes_",
    "tests/study/test_simulate_cli.py::test_bench_lcca_quick_",
    "tests/study/test_notes_cli.py::test_characterize_",
    "tests/db/test_migrations.py::test_two_processes_",
    "tests/db/test_samples.py::test_kill_9_",
    "tests/study/test_progress_lines.py::test_a_demo_into_a_log_file_",
)
"""Single tests (node id prefixes) marked `slow` in modules that are otherwise fast:
subprocesses, kill -9, memory measured over a large export, many simulated fits, a whole
probe session stored, exported and imported, hundreds of generated trial files, a GRU
trained for the loop to run, a demo run into a log file."""
FAST_LANE = "not slow"
"""The fast lane's mark expression (README): given exactly, the modules of
`SLOW_MODULES` are not even imported (PyTorch, the fit), which would all be deselected."""


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    if " ".join(str(config.getoption("markexpr") or "").split()) != FAST_LANE:
        return None
    root = Path(__file__).resolve().parent.parent
    try:
        relative = collection_path.resolve().relative_to(root).as_posix()
    except ValueError:
        return None
    return True if relative in SLOW_MODULES else None


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    root = Path(__file__).resolve().parent.parent
    for item in items:
        if Path(item.path).resolve().relative_to(
            root
        ).as_posix() in SLOW_MODULES or item.nodeid.startswith(SLOW_TESTS):
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def patient_host(monkeypatch: pytest.MonkeyPatch) -> None:
    """The host waits 0.2 s for a reply from a unit instead of two update periods: for the
    tests with host-built units in the loop, which a busy machine (the suite's other
    workers, the units' own processes) can hold up past 20 ms. A silent or unplugged unit
    is still found, 0.2 s later; the tests of how soon keep the default."""
    from teleop_core.loop import hardware

    init = hardware.Esp32Unit.__init__
    defaults = list(init.__defaults__ or ())
    names = init.__code__.co_varnames[: init.__code__.co_argcount]
    defaults[names[-len(defaults) :].index("timeout_s")] = 0.2
    monkeypatch.setattr(init, "__defaults__", tuple(defaults))
