"""Adding a task (README, "Adding a task"): a third task defined here, in its own module
and nowhere else, registered, and run through a session, the export, the analysis and
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
from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.trial import Trial
from study.cli import main
from study.protocol.tasks import (
    LiveTrace,
    Measure,
    SampleColumn,
    Task,
    get_task,
    pose_columns,
    register,
    unregister,
)
from teleop_core.loop.drivers import Driver, HandAction, OperatorView

DEPTH_M = 0.08
DAMPING_N_S_PER_M = 40.0
RATE_GAIN_M_S_PER_RAD = 0.05
AIM_RAD = 0.8
"""The simulated participant's aim, the same in every trial."""
RATE_HZ = 100.0


class ProbeDriver(Driver):
    """Aims the dial at a fixed angle until the probe is at depth."""

    rate_hz = 25.0

    def __init__(self, aim_rad: float) -> None:
        self.aim_rad = aim_rad

    def start(self, rng: np.random.Generator) -> None:
        pass

    def act(self, view: OperatorView) -> HandAction:
        return HandAction(done=True) if view.success else HandAction(dial_target_rad=self.aim_rad)


class ProbeLoop:
    """The task's loop: the dial's aim sets the probe's speed; the medium pushes back."""

    def __init__(self, condition: str) -> None:
        self.condition = condition
        self.t_s, self.depth_m, self.done, self.success = 0.0, 0.0, False, False

    def start(self, driver: Driver) -> None:
        self.driver = driver
        driver.start(np.random.default_rng(0))

    def advance(self, duration_s: float) -> np.ndarray:
        rows = []
        for _ in range(round(duration_s * RATE_HZ)):
            if self.done:
                break
            view = OperatorView(self.t_s, 0.0, 0.0, self.depth_m, 0.0, (self.depth_m, 0.0, 0.0),
                                "medium", self.success)  # fmt: skip
            action = self.driver.act(view)
            if action.done:
                self.done = True
                break
            speed = RATE_GAIN_M_S_PER_RAD * action.dial_target_rad
            self.t_s = round(self.t_s + 1 / RATE_HZ, 9)
            self.depth_m = min(self.depth_m + speed / RATE_HZ, DEPTH_M)
            self.success = self.depth_m >= DEPTH_M - 1e-12
            region = 1.0 if self.success else 0.0
            force = DAMPING_N_S_PER_M * speed
            rows.append([self.t_s, self.depth_m, 0.0, self.depth_m, 0.0, 0.0, region, force,
                         action.dial_target_rad])  # fmt: skip
        return np.array(rows, dtype=float).reshape(-1, 9)


class ProbeTask(Task):
    name = "probe"
    title = "Probe insertion"
    regions = ("medium", "depth")
    sample_columns = (
        *pose_columns(
            "probe depth",
            "probe roll (none)",
            "tip position",
            insertion_name="depth_m",
            rotation_name="roll_rad",
        ),
        SampleColumn("where", "branch", "", "medium or at depth"),
        SampleColumn("push_force_n", "proximal_force_n", "N", "the medium's push back"),
        SampleColumn("aim_rad", "dial_angle_rad", "rad", "the hand's aim"),
    )
    measures = (
        Measure(
            "peak_push_force_n",
            "N",
            "peak push force",
            "largest push of the medium",
            max_value=10.0,
        ),
    )
    live_traces = (LiveTrace("push_force_n", "push", 2.0), LiveTrace("aim_rad", "aim", 1.0))
    live_peaks = (LiveTrace("push_force_n", "push", 2.0), LiveTrace("aim_rad", "aim", 1.0))
    trace_names: ClassVar[dict[str, str]] = {"proximal_force_n": "push (medium)"}
    sign_note = "Push force: positive resists insertion."
    track_length_m = 0.1

    def make_loop(self, condition, seed, *, haptic_gain_n_m_per_n=None, estimator=None,
                  context=None, link=None):  # fmt: skip
        return ProbeLoop(condition)

    def simulated_driver(self, traits, max_s, context):
        return ProbeDriver(AIM_RAD)

    def trial_measures(self, samples, success):
        return {"peak_push_force_n": float(samples[:, 7].max())}, {}


@pytest.fixture
def probe() -> Iterator[ProbeTask]:
    task = register(ProbeTask())
    try:
        yield task
    finally:
        unregister(task.name)


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


def test_a_task_registered_here_runs_through_session_export_and_analysis(
    probe: ProbeTask, tmp_path: Path
) -> None:
    assert get_task("probe") is probe
    db = _study(tmp_path, 6)
    assert main(["run", "--all", "--jobs", "1", "--db", db]) == 0
    engine = open_database(db)
    with Session(engine) as session:
        trials = session.scalars(select(Trial)).all()
        assert len(trials) == 6 * 2 * 2 and {t.status for t in trials} == {"completed"}
        speed = RATE_GAIN_M_S_PER_RAD * AIM_RAD
        for t in trials:
            # hand-computed: F = B v at the constant aim, t = depth / v (to a 10 ms sample)
            assert t.measure_values == {"peak_push_force_n": pytest.approx(
                DAMPING_N_S_PER_M * speed)}  # fmt: skip
            assert t.completion_time_s == pytest.approx(DEPTH_M / speed, abs=0.011)
            assert t.success
    engine.dispose()
    # export: the task's measure under its own name, described in the codebook
    assert main(["export", "--out", str(tmp_path / "out"), "--db", db]) == 0
    exported = pd.read_csv(tmp_path / "out" / "trials.csv")
    assert list(exported.columns) == [
        "participant", "group", "task", "condition", "trial", "completion_time_s",
        "peak_push_force_n", "success",
    ]  # fmt: skip
    assert len(exported) == 24 and (exported["task"] == "probe").all()
    book = pd.read_csv(tmp_path / "out" / "codebook.csv").set_index("column")
    assert book.loc["peak_push_force_n", "unit"] == "N"
    assert "largest push of the medium" in book.loc["peak_push_force_n", "meaning"]
    # the exported file imports back into a fresh study of the same design
    db2 = str(tmp_path / "again.db")
    assert main(["init", "--design", str(tmp_path / "d.toml"), "--db", db2]) == 0
    assert main(["import", "--trials", str(tmp_path / "out" / "trials.csv"), "--db", db2]) == 0
    # analysis: the task's measures per group and condition
    out = tmp_path / "a.json"
    assert main(["analyze", "--out", str(tmp_path / "res"), "--json", str(out), "--db", db]) == 0
    report = json.loads(out.read_text())
    measures = {(d["task"], d["measure"]) for d in report["descriptives"]}
    assert {("probe", "completion_time_s"), ("probe", "peak_push_force_n")} <= measures
    assert main(["analyze", "--out", str(tmp_path / "res2"), "--task", "probe", "--db", db]) == 0


async def test_the_run_screen_shows_a_registered_task(probe: ProbeTask, tmp_path: Path) -> None:
    from study.protocol.default_estimator import load_estimator
    from study.tasks.notes.scene import NotesView
    from study.tui import StudyServices, TuiSettings, make_app
    from study.tui.confirm import Confirm
    from study.tui.live_view import PhantomView
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
        assert track.display and not app.query_one(PhantomView).display
        assert not app.query_one(NotesView).display
        assert app.query_one("#phantom-box").border_title == "Probe insertion: insertion"
        assert track._frame is not None and track._frame.task is probe
        # the last frame drawn (the trial may end between two redraws): the probe on its way
        drawn = re.search(r"inserted +(\d+) mm   in (medium|depth)", track.render().plain)
        assert drawn is not None and 0 < int(drawn.group(1)) <= 80
        # the peak shown when the trial ended is the stored measure
        peak = float(pane.last_outcome.split("peaks ")[1].split(" N push")[0])
    with Session(engine) as session:
        trial = session.scalars(select(Trial)).one()
    engine.dispose()
    assert peak == pytest.approx(trial.measure_values["peak_push_force_n"], abs=0.005)
