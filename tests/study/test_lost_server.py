"""A PostgreSQL server that ends `study run`'s connections mid-trial (a restart, a
dropped network, an administrator's `pg_terminate_backend`): one line naming the lost
connection (not a full disk), exit status 2, the trial left `running` with the samples
stored up to the line's time, and the next run marks it interrupted."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import make_url, text

from db.engine import make_engine
from study.cli import main
from study.protocol.design import TEMPLATE
from tests.conftest import PG_ENV

STUDY = [sys.executable, "-c", "import sys; from study.cli import main; sys.exit(main())"]


@pytest.fixture
def named_pg_url() -> Iterator[tuple[str, str]]:
    """A fresh schema's URL whose connections carry their own application name."""
    base = os.environ.get(PG_ENV)
    if not base:
        pytest.skip(f"{PG_ENV} is not set")
    schema = f"t_{uuid.uuid4().hex[:16]}"
    admin = make_engine(base)
    with admin.begin() as conn:
        conn.execute(text(f'CREATE SCHEMA "{schema}"'))
    url = make_url(base).update_query_dict(
        {"options": f"-csearch_path={schema}", "application_name": f"lost_{schema}"}
    )
    try:
        yield url.render_as_string(hide_password=False), f"lost_{schema}"
    finally:
        with admin.begin() as conn:
            conn.execute(text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


@pytest.mark.postgres
def test_connections_ended_mid_trial_read_as_disconnected(
    named_pg_url: tuple[str, str], tmp_path: Path
) -> None:
    url, app_name = named_pg_url
    (tmp_path / "d.toml").write_text(TEMPLATE)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", url]) == 0
    assert main(["participant", "add", "--group", "novice", "--db", url]) == 0
    run = subprocess.Popen(
        [*STUDY, "run", "--participant", "P001", "--pace", "1", "--db", url],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    watcher = make_engine(url.replace(f"application_name={app_name}", "application_name=w"))
    try:
        end = time.monotonic() + 120
        while True:
            with watcher.connect() as conn:
                running = conn.execute(
                    text("SELECT count(*) FROM trials WHERE status = 'running'")
                ).scalar()
            if running or time.monotonic() > end:
                break
            time.sleep(0.1)
        assert running == 1
        time.sleep(1.5)  # a second of samples stored first
        with watcher.begin() as conn:
            ended = conn.execute(
                text(
                    "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                    "WHERE application_name = :name"
                ),
                {"name": app_name},
            ).all()
        assert ended
        _, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    lines = err.strip().splitlines()
    assert run.returncode == 2, err
    assert len(lines) == 1, lines
    assert "terminating connection due to administrator command" in lines[0]
    assert "expected a connection that stays up" in lines[0]
    assert "free space" not in lines[0]
    assert "full" not in lines[0]
    kept = re.search(r"its samples up to t = ([0-9.]+) s", lines[0])
    assert kept, lines[0]
    with watcher.connect() as conn:
        status = conn.execute(text("SELECT status FROM trials")).scalars().all()
        last_s = conn.execute(text("SELECT max(t_last_s) FROM sample_chunks")).scalar()
    assert status == ["running"]
    assert float(kept.group(1)) == pytest.approx(last_s, abs=0.005)
    # the server back (it never left): the next run marks the trial and runs the rest
    assert main(["run", "--participant", "P001", "--db", url]) == 0
    with watcher.connect() as conn:
        statuses = dict(
            conn.execute(text("SELECT status, count(*) FROM trials GROUP BY status")).all()
        )
    assert statuses == {"completed": 8, "interrupted": 1}  # 2 blocks x (1 practice + 3)
    watcher.dispose()
