"""A paced simulated session with the Lab Streaming Layer: markers and samples out, an
outside instrument recorded in (the suite's loopback-only liblsl config, tests/conftest.py).
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.lsl_streams import read_stream
from db.migrate import open_database
from db.models.lsl import LslStream
from db.models.trial import Trial
from study.lsl.config import load_pylsl
from study.lsl.markers import MARKER_STREAM, parse
from study.lsl.publish import Publisher
from study.lsl.record import Recorder
from study.protocol.observer import Observers, SessionObserver, TrialInfo
from tests.study.conftest import init_study

DEVICE = Path(__file__).with_name("device.py")
DESIGN = """\
name = "lsl {tag}"
tasks = ["lcca"]
trials_per_condition = 1
practice_trials = 0
[groups]
novice = 1
[lsl]
publish = true
record = ["name='{device}'"]
"""
TRIAL_S = 1.5
"""Each trial's length: the simulated person gives up then (the session stays short)."""


@dataclass
class Origins(SessionObserver):
    """The trials' clocks as the runner hands them out (the reference for alignment)."""

    trials: dict[int, TrialInfo] = field(default_factory=dict)
    lag_s: dict[int, float] = field(default_factory=dict)
    """Per trial: the most the loop fell behind its clock at a step, trial seconds (the
    runner keeps pace within a step; a loaded machine can hold it back longer)."""

    def trial_started(self, trial: TrialInfo) -> None:
        self.trials[trial.trial_id] = trial
        self.lag_s[trial.trial_id] = 0.0

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        if len(rows):
            due = (time.monotonic() - trial.clock_origin_s) * trial.clock_rate
            lag = due - float(rows[-1, 0])
            self.lag_s[trial.trial_id] = max(self.lag_s[trial.trial_id], lag)


def _device(name: str, seconds: float, log: Path) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, str(DEVICE), name, "EMG", "1000", str(seconds), str(log)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"
    return proc


def _session(
    db: str,
    observers: list[SessionObserver],
    max_trials: int | None = None,
    trial_s: float = TRIAL_S,
) -> list[int]:
    from study.protocol.default_estimator import load_estimator
    from study.protocol.session import participant_traits, run_session
    from study.protocol.session_settings import SessionSettings
    from study.tasks.lcca.simulated_participant import SimulatedParticipant
    from teleop_core.phantom.lcca import LccaPhantom

    engine = open_database(db, create=False)
    phantom = LccaPhantom()
    traits = participant_traits(1, "P001", "novice")
    try:
        settings = SessionSettings(
            "simulated",
            load_estimator(),
            make_driver=lambda: SimulatedParticipant(traits, phantom, give_up_s=trial_s),
            pace=1.0,
            max_trials=max_trials,
        )
        return run_session(engine, "P001", settings, Observers(observers))
    finally:
        engine.dispose()


class MarkerInlet(threading.Thread):
    """A marker inlet as a lab's recorder would open it: every marker, with its stamp."""

    def __init__(self, source_id: str) -> None:
        super().__init__(daemon=True)
        self.source_id = source_id
        self.markers: list[tuple[float, str]] = []
        self.connected = threading.Event()

    def run(self) -> None:
        pylsl = load_pylsl()
        pred = f"name='{MARKER_STREAM}' and source_id='{self.source_id}'"
        found = []
        while not found:
            found = pylsl.resolve_bypred(pred, 1, 1.0)
        inlet = pylsl.StreamInlet(found[0])
        inlet.open_stream(10.0)
        self.connected.set()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            sample, stamp = inlet.pull_sample(0.5)
            if sample is not None:
                self.markers.append((stamp, sample[0]))
                if '"session_end"' in sample[0]:
                    return


class SampleInlet(threading.Thread):
    """An inlet on the session's sample stream of a task: its description and samples."""

    def __init__(self, source_id: str, done: threading.Event) -> None:
        super().__init__(daemon=True)
        self.source_id, self.done = source_id, done
        self.channels: list[tuple[str, str]] = []
        self.rate_hz = 0.0
        self.rows: list[np.ndarray] = []
        self.stamps: list[float] = []

    def run(self) -> None:
        pylsl = load_pylsl()
        found = []
        while not found and not self.done.is_set():
            found = pylsl.resolve_bypred(f"source_id='{self.source_id}'", 1, 0.5)
        if not found:
            return
        inlet = pylsl.StreamInlet(found[0])
        info = inlet.info(5.0)
        self.rate_hz = info.nominal_srate()
        ch = info.desc().child("channels").child("channel")
        while not ch.empty():
            self.channels.append((ch.child_value("label"), ch.child_value("unit")))
            ch = ch.next_sibling()
        idle_since = None
        while True:
            rows, stamps = inlet.pull_chunk(timeout=0.2)
            if stamps:
                self.rows.append(np.asarray(rows))
                self.stamps += stamps
                idle_since = None
            elif self.done.is_set():
                idle_since = idle_since or time.monotonic()
                if time.monotonic() - idle_since > 1.0:
                    return


@pytest.fixture(scope="module")
def paced(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """One paced session of two 1.5 s trials: an instrument at 1 kHz streaming throughout,
    the session publishing, a marker inlet listening."""
    tmp = tmp_path_factory.mktemp("lsl")
    tag = uuid.uuid4().hex[:8]
    device = f"emg-{tag}"
    db = init_study(tmp, DESIGN.format(tag=tag, device=device), ("novice",))
    log = tmp / "device.log"
    proc = _device(device, 30.0, log)
    listener = MarkerInlet(f"haptic-study/lsl {tag}/P001")
    listener.start()
    ended = threading.Event()
    samples = SampleInlet(f"haptic-study/lsl {tag}/P001/lcca", ended)
    samples.start()
    origins, notices = Origins(), []
    engine = open_database(db, create=False)
    try:
        observers = [
            origins,
            Publisher(wait_for_consumers_s=20.0),
            Recorder(engine, (f"name='{device}'",), notices.append),
        ]
        completed = _session(db, observers)
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    listener.join(timeout=20)
    ended.set()
    samples.join(timeout=20)
    return {
        "db": db,
        "engine": engine,
        "completed": completed,
        "origins": origins,
        "markers": listener.markers,
        "notices": notices,
        "samples": samples,
    }


def test_an_outside_instrument_is_stored_sample_for_sample_on_the_trials_clock(
    paced: dict[str, Any],
) -> None:
    engine, origins = paced["engine"], paced["origins"]
    assert len(paced["completed"]) == 2
    assert paced["notices"] == []
    with Session(engine) as s:
        streams = s.scalars(select(LslStream).order_by(LslStream.trial_id)).all()
        ends = dict(s.execute(select(Trial.id, Trial.completion_time_s)).all())
    assert [st.trial_id for st in streams] == paced["completed"]
    previous_last = -1
    for stream in streams:
        assert stream.type == "EMG"
        assert stream.nominal_srate_hz == 1000.0
        assert [c["name"] for c in stream.channels] == ["index", "made_s"]
        assert [c["unit"] for c in stream.channels] == ["count", "s"]
        assert stream.gaps == []
        table = read_stream(engine, stream.id)
        index = table["index"].to_numpy()
        # sample for sample: every sample the device made during the trial, once, in order
        assert np.array_equal(index, np.arange(index[0], index[0] + len(index)))
        assert index[0] > previous_last
        previous_last = index[-1]
        trial = origins.trials[stream.trial_id]
        # where each sample belongs on the trial's clock, from when the device made it
        expected = (table["made_s"].to_numpy() - trial.clock_origin_s) * trial.clock_rate
        error_s = table["t_s"].to_numpy() - expected
        # while the loop keeps pace, the trial's clock; where it falls behind (a loaded
        # machine), the loop's progress: never later than made, earlier by at most the
        # loop's lag
        lag_s = origins.lag_s[stream.trial_id]
        assert np.median(np.abs(error_s)) <= 0.002 + lag_s
        assert np.percentile(np.abs(error_s), 95) <= 0.005 + lag_s
        assert error_s.max() <= 0.005
        # the whole trial is covered: from its start to its end, at 1 kHz
        t = table["t_s"].to_numpy()
        # (within a few periods: the device's process may wait for a core at either end)
        end = ends[stream.trial_id]
        assert 0 <= t[0] <= 0.05
        assert end - 0.05 <= t[-1] <= end
        assert len(t) == pytest.approx(end * 1000, rel=0.05)


def test_a_marker_inlet_receives_every_marker_in_order_with_the_databases_trials(
    paced: dict[str, Any],
) -> None:
    markers = [(stamp, parse(text)) for stamp, text in paced["markers"]]
    assert all(m is not None for _, m in markers)
    events = [m["event"] for _, m in markers]
    assert events == [
        "session_start",
        "trial_start",
        "trial_end",
        "trial_start",
        "trial_end",
        "session_end",
    ]
    stamps = [stamp for stamp, _ in markers]
    assert stamps == sorted(stamps)
    with Session(paced["engine"]) as s:
        trials = s.scalars(select(Trial).order_by(Trial.id)).all()
        rows = [
            (
                t.id,
                t.participant.code,
                t.participant.group,
                t.task,
                t.condition,
                t.block_index,
                t.trial_index,
                t.practice,
                t.success,
            )
            for t in trials
        ]
    starts = [m for _, m in markers if m["event"] == "trial_start"]
    ends = [m for _, m in markers if m["event"] == "trial_end"]
    for start, end, row in zip(starts, ends, rows, strict=True):
        for m in (start, end):
            got = (
                m["trial_id"],
                m["participant"],
                m["group"],
                m["task"],
                m["condition"],
                m["block"],
                m["trial"],
                m["practice"],
            )
            assert got == row[:8]
        assert end["status"] == "completed"
        assert end["success"] == row[8]
    # a trial's start marker is stamped at its t = 0, its end at its last sample
    origins = paced["origins"].trials
    pylsl = load_pylsl()
    offset = pylsl.local_clock() - time.monotonic()
    for stamp, m in markers:
        if m["event"] == "trial_start":
            assert stamp - offset == pytest.approx(origins[m["trial_id"]].clock_origin_s, abs=0.002)


@dataclass
class Unplug(SessionObserver):
    """Kills the instrument's process once the trial's clock reaches `at_s`."""

    proc: subprocess.Popen[str]
    at_s: float

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        if len(rows) and rows[-1, 0] >= self.at_s and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def test_a_stream_lost_mid_trial_is_a_recorded_gap_and_the_trial_completes(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    tag = uuid.uuid4().hex[:8]
    device = f"emg-{tag}"
    design = DESIGN.format(tag=tag, device=device).replace("publish = true", "publish = false")
    db = init_study(tmp_path, design, ("novice",))
    proc = _device(device, 30.0, tmp_path / "device.log")
    notices: list[str] = []
    engine = open_database(db, create=False)
    try:
        recorder = Recorder(engine, (f"name='{device}'",), notices.append)
        completed = _session(db, [recorder, Unplug(proc, 1.0)], max_trials=1, trial_s=2.5)
    finally:
        proc.kill()
        proc.wait(timeout=10)
    with Session(engine) as s:
        trial = s.get_one(Trial, completed[0])
        stream = s.scalars(select(LslStream)).one()
        assert trial.status == "completed"
        assert trial.completion_time_s >= 2.5
        gaps, end_s = stream.gaps, trial.completion_time_s
    t = read_stream(engine, stream.id)["t_s"].to_numpy()
    engine.dispose()
    # one gap, from the last sample before the instrument died to the trial's end
    assert len(gaps) == 1
    # (the paced loop makes a step's samples up to a step, 50 ms, before their time)
    assert gaps[0][0] == pytest.approx(t[-1])
    assert 0.85 <= gaps[0][0] <= 1.2
    assert gaps[0][1] == pytest.approx(end_s)
    assert len(notices) == 1
    assert f"LSL stream {device} (EMG) lost at t = " in notices[0]
    assert "broke off" not in capfd.readouterr().err  # that line is the one on screen


def test_the_trials_samples_go_out_with_the_tasks_channels_units_and_clock(
    paced: dict[str, Any],
) -> None:
    from db.sample_reader import SampleReader
    from study.protocol.tasks import get_task

    task = get_task("lcca")
    inlet = paced["samples"]
    assert inlet.channels == [(c.name, c.unit) for c in task.sample_columns]
    assert inlet.rate_hz == 100.0  # the loop's acquisition rate ([endovascular], IV-A)
    rows, stamps = np.concatenate(inlet.rows), np.asarray(inlet.stamps)
    # every stored sample of both trials, in order, as stored
    engine = paced["engine"]
    stored = []
    with SampleReader(engine) as reader:
        for trial_id in paced["completed"]:
            stored += [b.column("t_s").to_numpy() for b in reader.trial(trial_id)]
    t_stored = np.concatenate(stored)
    np.testing.assert_array_equal(rows[:, 0], t_stored)
    # each stamped at its trial's start (the trial_start marker) plus its time
    starts = [(stamp, parse(text)) for stamp, text in paced["markers"]]
    starts = [stamp for stamp, m in starts if m["event"] == "trial_start"]
    trial_of = np.cumsum(np.r_[0, np.diff(rows[:, 0]) < 0])
    np.testing.assert_allclose(stamps, np.asarray(starts)[trial_of] + rows[:, 0], atol=1e-6)


@dataclass
class Stall(SessionObserver):
    """Holds the session's thread once, when the trial reaches `at_s`: the loop falls
    behind the wall clock by `for_s` (a busy machine)."""

    at_s: float
    for_s: float
    held: list[float] = field(default_factory=list)

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        if len(rows) and rows[-1, 0] >= self.at_s and not self.held:
            self.held += [time.monotonic(), float(rows[-1, 0])]
            time.sleep(self.for_s)
            self.held.append(time.monotonic())


def test_an_instrument_lines_up_with_the_loop_that_fell_behind(tmp_path: Path) -> None:
    """While the loop stands still, the instrument's samples stay within a step of the
    time the loop has reached (the trial's clock until then), not on the wall clock's
    trial time, 0.4 s further on; nothing lands after the trial's last sample."""
    tag = uuid.uuid4().hex[:8]
    device = f"emg-{tag}"
    design = DESIGN.format(tag=tag, device=device).replace("publish = true", "publish = false")
    db = init_study(tmp_path, design, ("novice",))
    proc = _device(device, 30.0, tmp_path / "device.log")
    engine = open_database(db, create=False)
    stall, origins = Stall(at_s=0.5, for_s=0.4), Origins()
    try:
        recorder = Recorder(engine, (f"name='{device}'",))
        completed = _session(db, [origins, recorder, stall], max_trials=1, trial_s=1.5)
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    with Session(engine) as s:
        end_s = s.get_one(Trial, completed[0]).completion_time_s
        stream = s.scalars(select(LslStream)).one()
    table = read_stream(engine, stream.id)
    engine.dispose()
    t, made = table["t_s"].to_numpy(), table["made_s"].to_numpy()
    assert t[-1] <= end_s
    # the loop had made its samples up to `loop_t` and stood still from `held_from` to
    # `held_to` (wall clock), then made its next step (0.05 s): a sample made meanwhile is
    # on the trial's clock until that reaches `loop_t`, then between `loop_t` and the next
    # step's end (the recorder knows when each step was done, not how it went)
    held_from, loop_t, held_to = stall.held
    during = (made > held_from + 0.01) & (made < held_to - 0.01)
    assert during.sum() > 300  # about 0.38 s at 1 kHz
    trial = origins.trials[completed[0]]
    clock = (made[during] - trial.clock_origin_s) * trial.clock_rate
    low = np.minimum(clock, loop_t) - 0.002
    assert np.all((low <= t[during]) & (t[during] <= loop_t + 0.05 + 0.002))
    assert clock[-1] > loop_t + 0.3  # the trial's clock ran on: not what was stored
