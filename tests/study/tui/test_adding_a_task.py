"""Adding a task (README, "Adding a task"): the worked example `examples/probe_task`, a
package of its own that haptic-study does not name, installed here through its entry
point and run through a session, the export, the import, the analysis, the figures and
the TUI's run screen.

The task: push a probe 80 mm into a homogeneous medium. The medium resists with a
viscous force, F = B v (B = 40 N s/m), so at the simulated participant's constant aim the
probe's speed is the dial's aim times the rate gain and the stored peak push force has
the closed form B * gain * aim; the completion time is depth / speed (to the 10 ms
sample). Those two hand-computed values are what the stored measures are checked
against.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

import study.protocol.tasks as registry
from db.migrate import open_database
from db.models.trial import Trial
from study.cli import main
from study.protocol.tasks import get_task, unregister

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "probe_task"
DEPTH_M = 0.08
DAMPING_N_S_PER_M = 40.0
RATE_GAIN_M_S_PER_RAD = 0.05
AIM_RAD = 0.8
"""The example's values (`haptic_study_probe.loop`), written here again by hand."""


@pytest.fixture(scope="module")
def probe_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The example installed as a package (its wheel built from its pyproject) into a
    folder of its own, from a copy so that the build leaves the checkout as it was."""
    root = tmp_path_factory.mktemp("probe")
    shutil.copytree(EXAMPLE, root / "src")
    site = root / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-index",
            "--no-build-isolation",
            "--target",
            str(site),
            str(root / "src"),
        ],
        check=True,
    )
    return site


@pytest.fixture
def probe(probe_site: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """The installed example on the path; the registry finds it by its entry point."""
    monkeypatch.syspath_prepend(str(probe_site))
    monkeypatch.setattr(registry, "_ENTRY_POINTS_LOADED", False)
    try:
        yield get_task("probe")
    finally:
        unregister("probe")
        for name in [m for m in sys.modules if m.startswith("haptic_study_probe")]:
            del sys.modules[name]


def test_the_example_is_found_through_its_entry_point(probe: Any, probe_site: Path) -> None:
    assert type(probe).__module__ == "haptic_study_probe.task"
    assert Path(sys.modules["haptic_study_probe.task"].__file__).is_relative_to(probe_site)
    assert "probe" in registry.task_names()


DESIGN = """\
name = "probe study"
seed = 5
tasks = ["probe"]
trials_per_condition = 2
practice_trials = 0
[groups]
novice = 3
expert = 3
"""


def _study(tmp_path: Path, n: int) -> str:
    db = str(tmp_path / "probe.db")
    (tmp_path / "d.toml").write_text(DESIGN)
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db]) == 0
    for k in range(n):
        group = "novice" if k % 2 == 0 else "expert"
        assert main(["participant", "add", "--group", group, "--db", db]) == 0
    return db


def test_the_example_task_runs_through_session_export_import_analysis_and_figures(
    probe: Any, tmp_path: Path
) -> None:
    assert get_task("probe") is probe
    db = _study(tmp_path, 6)
    assert main(["run", "--all", "--jobs", "1", "--db", db]) == 0
    engine = open_database(db)
    with Session(engine) as session:
        trials = session.scalars(select(Trial)).all()
        assert len(trials) == 6 * 2 * 2
        assert {t.status for t in trials} == {"completed"}
        speed = RATE_GAIN_M_S_PER_RAD * AIM_RAD
        for t in trials:
            # hand-computed: F = B v at the constant aim, t = depth / v (to a 10 ms sample)
            assert t.measure_values == {
                "peak_push_force_n": pytest.approx(DAMPING_N_S_PER_M * speed)
            }
            assert t.completion_time_s == pytest.approx(DEPTH_M / speed, abs=0.011)
            assert t.success
    engine.dispose()
    # export: the task's measure under its own name, described in the codebook
    assert main(["export", "--out", str(tmp_path / "out"), "--db", db]) == 0
    exported = pd.read_csv(tmp_path / "out" / "trials.csv")
    assert list(exported.columns) == [
        "participant",
        "group",
        "task",
        "condition",
        "trial",
        "completion_time_s",
        "peak_push_force_n",
        "success",
        # the provenance an analysis re-run from the export needs
        "block",
        "data_source",
        "driver",
        "withdrawn",
        "valid",
        "invalid_reason",
        "included",
    ]
    assert len(exported) == 24
    assert (exported["task"] == "probe").all()
    book = pd.read_csv(tmp_path / "out" / "codebook.csv").set_index("column")
    assert book.loc["peak_push_force_n", "unit"] == "N"
    assert "largest push of the medium" in book.loc["peak_push_force_n", "meaning"]
    # the samples under the task's own columns, its unstored-before speed column too:
    # v = k_v * aim at every sample (hand-computed above)
    assert main(["export", "--out", str(tmp_path / "s"), "--samples", "--db", db]) == 0
    samples = pd.read_csv(tmp_path / "s" / "samples.csv")
    assert list(samples.columns) == [
        "participant",
        "task",
        "condition",
        "trial",
        "seq",
        "t_s",
        "depth_m",
        "roll_rad",
        "tip_x_m",
        "tip_y_m",
        "tip_z_m",
        "where",
        "push_force_n",
        "aim_rad",
        "medium_speed_m_s",
    ]
    assert samples["medium_speed_m_s"].to_numpy() == pytest.approx(speed)
    assert set(samples["where"]) == {"medium", "depth"}
    book = pd.read_csv(tmp_path / "s" / "codebook.csv").set_index("column")
    assert book.loc["medium_speed_m_s", "unit"] == "m/s"
    # the exported file imports back into a fresh study of the same design
    db2 = str(tmp_path / "again.db")
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db2]) == 0
    assert (
        main(
            ["import", "--enrol-new", "--trials", str(tmp_path / "out" / "trials.csv"), "--db", db2]
        )
        == 0
    )
    # analysis: the task's measures per group and condition
    out = tmp_path / "a.json"
    assert main(["analyze", "--out", str(tmp_path / "res"), "--json", str(out), "--db", db]) == 0
    report = json.loads(out.read_text())
    measures = {(d["task"], d["measure"]) for d in report["descriptives"]}
    assert {("probe", "completion_time_s"), ("probe", "peak_push_force_n")} <= measures
    assert main(["analyze", "--out", str(tmp_path / "res2"), "--task", "probe", "--db", db]) == 0
    # figures: the task's own set, named after it
    figures = tmp_path / "figs"
    assert main(["figures", "--out", str(figures), "--format", "png", "--db", db]) == 0
    drawn = sorted(p.name for p in figures.glob("*.png"))
    assert drawn, drawn
    assert all(name.endswith("_probe.png") for name in drawn), drawn


async def test_the_run_screen_shows_the_example_task(probe: Any, tmp_path: Path) -> None:
    from study.protocol.default_estimator import load_estimator
    from study.tui import StudyServices, TuiSettings, make_app
    from study.tui.confirm import Confirm
    from study.tui.scene_lcca import PhantomView
    from study.tui.scene_notes import NotesView
    from study.tui.scenes import TrackView
    from tests.study.tui.conftest import run_screen, wait_for

    db = _study(tmp_path, 1)
    engine = open_database(db)
    services = StudyServices(engine, load_estimator)
    # at real time (the trial lasts 2 s), so that the 30 Hz view draws it
    app = make_app(services, TuiSettings(simulated_pace=1.0, figures_dir=tmp_path / "f"))
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await run_screen(pilot, "P001")
        await pilot.press("s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")
        await wait_for(pilot, lambda: pane.status == "completed", 60)
        track = app.query_one(TrackView)
        assert track.display
        assert not app.query_one(PhantomView).display
        assert not app.query_one(NotesView).display
        assert app.query_one("#phantom-box").border_title == "Probe insertion: insertion"
        assert track._frame is not None
        assert track._frame.task is probe
        # the last frame drawn (the trial may end between two redraws): the probe on its way
        drawn = re.search(r"inserted +(\d+) mm   in (medium|depth)", track.render().plain)
        assert drawn is not None
        assert 0 < int(drawn.group(1)) <= 80
        # the peak shown when the trial ended is the stored measure (the trial's line;
        # the block's summary, of this one trial, repeats it)
        shown = next(
            line for line in pane.last_outcome.split("\n") if line.startswith("  peak push force ")
        )
        peak = float(shown.split()[3])
    with Session(engine) as session:
        trial = session.scalars(select(Trial)).one()
    engine.dispose()
    assert peak == pytest.approx(trial.measure_values["peak_push_force_n"], abs=0.005)
