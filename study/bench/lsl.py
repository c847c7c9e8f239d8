"""`study bench lsl`: how well recorded streams line up with the trial's clock.

A paced simulated session (pace 1, in a scratch SQLite study) records a SIMULATED
instrument (`study.lsl.sim_device`, another process, 1 kHz, each sample carrying the
`time.monotonic()` at which it was made) while publishing its own markers and samples.
For every stored sample, the alignment error is its stored time on the trial's clock
minus where it belongs: `(made_s - clock_origin_s) * clock_rate`, with the trial's
clock as the session runner hands it out (`study.protocol.observer`). The cost of
publishing on the loop's speed is `study bench lcca` with and without `--lsl`.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
import uuid
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from study.protocol.observer import Observers, SessionObserver, TrialInfo
from teleop_core.progress import Progress, no_progress

SIMULATED_NOTE = (
    "SIMULATED: a simulated participant in the simulated LCCA loop, and a simulated "
    "1 kHz instrument on this machine's loopback; no measured data"
)


@dataclass(frozen=True)
class LslBenchConfig:
    trials: int = 4
    trial_s: float = 5.0
    """Each trial's length (the simulated person gives up then), s."""
    rate_hz: float = 1000.0

    @classmethod
    def quick(cls) -> LslBenchConfig:
        return cls(trials=2, trial_s=2.0)


class Origins(SessionObserver):
    """The trials' clocks, and where the loop's newest sample stood against the wall
    clock after each step (the runner paces to within a step)."""

    def __init__(self) -> None:
        self.trials: dict[int, TrialInfo] = {}
        self.lead_s: list[float] = []

    def trial_started(self, trial: TrialInfo) -> None:
        self.trials[trial.trial_id] = trial

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        if len(rows):
            due = trial.clock_origin_s + rows[-1, 0] / trial.clock_rate
            self.lead_s.append(due - time.monotonic())


def run_lsl_bench(
    config: LslBenchConfig, out_dir: Path, progress: Progress = no_progress
) -> dict[str, Any]:
    """Run the bench (module docstring); writes lsl_bench.json and .md to `out_dir`."""
    # lazy: study.lsl.publish (with pandas, pyarrow, numpy) costs 0.3 s at start-up
    from study.lsl.publish import Publisher

    # lazy: study.lsl.record (with pyarrow, sqlalchemy) costs 0.4 s at start-up
    from study.lsl.record import Recorder

    out_dir.mkdir(parents=True, exist_ok=True)
    name = f"sim-emg-{uuid.uuid4().hex[:8]}"
    with tempfile.TemporaryDirectory() as tmp:
        engine, code = _scratch_study(Path(tmp), config.trials)
        seconds = config.trials * (config.trial_s + 2.0) + 20.0
        device = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "study.lsl.sim_device",
                name,
                "EMG",
                str(config.rate_hz),
                str(seconds),
                f"{tmp}/device.log",
            ],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            if device.stdout is None or device.stdout.readline().strip() != "ready":
                raise RuntimeError("the simulated instrument did not start")
            origins = Origins()
            notices: list[str] = []
            recorder = Recorder(engine, (f"name='{name}'",), notices.append)
            progress(f"paced session: {config.trials} trials of {config.trial_s:g} s")
            start = time.monotonic()
            completed = _paced_session(engine, code, config, [origins, Publisher(), recorder])
            wall_s = time.monotonic() - start
        finally:
            device.terminate()
            device.wait(timeout=10)
        errors, per_trial = _alignment(engine, origins)
        engine.dispose()
    err = np.abs(np.concatenate(errors))
    report = {
        "config": asdict(config),
        "data": SIMULATED_NOTE,
        "trials_completed": len(completed),
        "session_wall_s": wall_s,
        "alignment": {
            "samples": len(err),
            "median_abs_error_ms": float(np.median(err) * 1e3),
            "p95_abs_error_ms": float(np.percentile(err, 95) * 1e3),
            "max_abs_error_ms": float(err.max() * 1e3),
            "signed_median_error_ms": float(np.median(np.concatenate(errors)) * 1e3),
        },
        "pacing": {
            "steps": len(origins.lead_s),
            "median_lead_ms": float(np.median(origins.lead_s) * 1e3),
            "max_lead_ms": float(np.max(origins.lead_s) * 1e3),
            "min_lead_ms": float(np.min(origins.lead_s) * 1e3),
        },
        "per_trial": per_trial,
        "gap_notices": notices,
    }
    (out_dir / "lsl_bench.json").write_text(json.dumps(report, indent=2) + "\n")
    (out_dir / "lsl_bench.md").write_text(markdown(report))
    return report


def _scratch_study(folder: Path, trials: int) -> tuple[Any, str]:
    """A study of one novice with `trials` LCCA trials in a SQLite file in `folder`."""
    # lazy: db.migrate (with sqlalchemy) costs 0.3 s at start-up
    from db.migrate import open_database

    # lazy: study.protocol.design costs 17 ms at start-up
    from study.protocol.design import parse_design

    # lazy: study.protocol.roster (with sqlalchemy) costs 0.3 s at start-up
    from study.protocol.roster import add_participant, create_study

    text = (
        f'name = "lsl bench"\ntasks = ["lcca"]\ntrials_per_condition = {-(-trials // 2)}\n'
        "practice_trials = 0\n[groups]\nnovice = 1\n"
    )
    engine = open_database(f"sqlite:///{folder}/bench.db", create=True)
    create_study(engine, parse_design(text), text)
    return engine, add_participant(engine, "novice").code


def _paced_session(
    engine: Any, code: str, config: LslBenchConfig, observers: list[SessionObserver]
) -> list[int]:
    """The participant's trials at real time, each ended after `config.trial_s`."""
    # lazy: study.protocol.default_estimator (with pandas, pyarrow, numpy) costs 0.3 s at start-up
    from study.protocol.default_estimator import load_estimator

    # lazy: study.protocol.session (with pandas, pyarrow, sqlalchemy) costs 0.7 s at start-up
    from study.protocol.session import participant_traits, run_session
    from study.protocol.session_settings import SessionSettings

    # lazy: study.tasks.lcca.simulated_participant costs 38 ms at start-up
    from study.tasks.lcca.simulated_participant import SimulatedParticipant

    # lazy: teleop_core.phantom.lcca costs 9 ms at start-up
    from teleop_core.phantom.lcca import LccaPhantom

    phantom = LccaPhantom()
    traits = participant_traits(1, code, "novice")
    settings = SessionSettings(
        "simulated",
        load_estimator(),
        make_driver=lambda: SimulatedParticipant(traits, phantom, give_up_s=config.trial_s),
        pace=1.0,
        max_trials=config.trials,
    )
    return run_session(engine, code, settings, Observers(observers))


def _alignment(engine: Any, origins: Origins) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
    """Per stored stream: each sample's stored trial time minus where it belongs."""
    # lazy: sqlalchemy costs 0.2 s at start-up
    from sqlalchemy import select

    # lazy: sqlalchemy.orm costs 0.3 s at start-up
    from sqlalchemy.orm import Session

    # lazy: db.lsl_streams (with pyarrow, sqlalchemy) costs 0.3 s at start-up
    from db.lsl_streams import read_stream

    # lazy: db.models.lsl (with sqlalchemy) costs 0.3 s at start-up
    from db.models.lsl import LslStream

    with Session(engine) as s:
        streams = s.scalars(select(LslStream).order_by(LslStream.trial_id)).all()
        s.expunge_all()
    errors, per_trial = [], []
    for stream in streams:
        table = read_stream(engine, stream.id)
        trial = origins.trials[stream.trial_id]
        expected = (table["made_s"].to_numpy() - trial.clock_origin_s) * trial.clock_rate
        err = table["t_s"].to_numpy() - expected
        index = table["index"].to_numpy()
        errors.append(err)
        consecutive = np.array_equal(index, np.arange(index[0], index[0] + len(index)))
        per_trial.append(
            {
                "trial_id": stream.trial_id,
                "samples": len(err),
                "consecutive": bool(consecutive),
                "median_abs_error_ms": float(np.median(np.abs(err)) * 1e3),
            }
        )
    return errors, per_trial


def markdown(report: dict[str, Any]) -> str:
    a = report["alignment"]
    c = report["config"]
    return "\n".join(
        [
            "# Recorded LSL streams against the trial's clock",
            "",
            f"{report['data']}.",
            "",
            f"{report['trials_completed']} paced trials of {c['trial_s']:g} s, a "
            f"{c['rate_hz']:g} Hz instrument: {a['samples']} samples stored.",
            "",
            "| alignment error | ms |",
            "|---|---|",
            f"| median abs | {a['median_abs_error_ms']:.3f} |",
            f"| 95th percentile abs | {a['p95_abs_error_ms']:.3f} |",
            f"| max abs | {a['max_abs_error_ms']:.3f} |",
            f"| median signed | {a['signed_median_error_ms']:+.3f} |",
            "",
            "Every trial's samples consecutive (none lost or repeated): "
            f"{all(t['consecutive'] for t in report['per_trial'])}.",
            "",
            "The trial's own samples: after each step the loop's newest sample was due "
            f"{report['pacing']['median_lead_ms']:.1f} ms ahead of the wall clock (median; "
            f"from {report['pacing']['min_lead_ms']:.1f} to {report['pacing']['max_lead_ms']:.1f}"
            " ms): a paced simulated loop computes a step before the runner waits for it.",
            "",
        ]
    )
