"""Streams out: the session's markers and each running trial's samples, as LSL streams.

A `Publisher` is a session observer (`study.protocol.observer`). At the session's start
it opens the marker outlet (`study.lsl.markers`). A running trial's samples go out on
the sample outlet of its task, `haptic-study <task>` (type `SAMPLE_STREAM_TYPE`), with
the task's own sample columns as channels (label, unit, description in the stream's XML
`desc`; the region column is the index into the `<regions>` listed there), at the
loop's acquisition rate, each sample stamped at `t0 + t_s / clock_rate` on the LSL
clock, where `t0` is the trial's start (its `trial_start` marker's stamp). The outlets
of the session's tasks open with the session and stay open, carrying each trial in turn
(the markers say which): LabRecorder records the streams chosen when its recording
starts, so an outlet opened per trial would go unrecorded, and opening and closing one
costs tens of ms of the loop's time. Their declared rate is the loop's acquisition
rate (`teleop_core.loop.config.LoopConfig`); a task whose rows come at another rate
gets its outlet opened again at that rate with its first trial. An unpaced simulated
session runs faster than real time, so its stamps run ahead of the wall clock (the
trial's own clock).
"""

from __future__ import annotations

import platform
import threading
import time
from types import ModuleType
from typing import Any

import numpy as np

from study.lsl.clock import monotonic_to_lsl
from study.lsl.config import load_pylsl
from study.lsl.markers import MARKER_STREAM, MARKER_TYPE, SAMPLE_STREAM_TYPE, encode
from study.protocol.observer import SessionInfo, SessionObserver, TrialInfo
from study.protocol.tasks import Task
from teleop_core.loop.config import LoopConfig

ACQUISITION_RATE_HZ = LoopConfig().acquisition_rate_hz
"""The rate the sample outlets are declared at until a trial's rows say otherwise."""


CLOSE_AFTER_S = 2.0
"""How long a closed outlet lingers before it is destroyed: liblsl drops what an outlet
has queued but not yet sent when it is destroyed, so a marker pushed just before (the
session's end) could miss a subscribed recorder on a busy machine."""


def _close_later(outlets: list[Any]) -> None:
    """Drop `outlets` (the only references to them) in a thread of its own, after
    `CLOSE_AFTER_S`: liblsl's destructor waits for an outlet's network threads to end
    (tens of ms), and the wait lets the last pushed samples leave."""
    outlets[:] = [o for o in outlets if o is not None]
    if outlets:

        def close() -> None:
            time.sleep(CLOSE_AFTER_S)
            outlets.clear()

        # not a daemon: a command that ends right after waits for its last markers to leave
        threading.Thread(target=close, daemon=False).start()


class Publisher(SessionObserver):
    """Publish a session's markers and samples (see the module docstring).

    Parameters
    ----------
    wait_for_consumers_s
        At the session's start, wait up to this long for a recorder to subscribe to each
        of its streams (what is pushed before anyone listens reaches no one), s.
    pylsl
        The pylsl module (default: `study.lsl.config.load_pylsl()`).
    sample_streams
        Open each task's sample stream with the session (False: markers only, for what
        happens outside trials: probes, a stored questionnaire).
    """

    def __init__(
        self,
        wait_for_consumers_s: float = 0.0,
        pylsl: ModuleType | None = None,
        sample_streams: bool = True,
    ):
        self.lsl = pylsl or load_pylsl()
        self.wait_for_consumers_s = wait_for_consumers_s
        self.sample_streams = sample_streams
        self.offset_s = monotonic_to_lsl(self.lsl)
        self.markers: Any = None
        self.session: SessionInfo | None = None
        self.outlets: dict[str, Any] = {}
        """The sample outlet of each task, by name."""
        self._checked: dict[str, bool] = {}
        self._t0_lsl = 0.0
        self.pushed = 0

    # -- markers ----------------------------------------------------------------------

    def _mark(self, event: str, stamp: float, **fields: Any) -> None:
        if self.markers is None or self.session is None:
            return
        s = self.session
        keys = {"study": s.study, "participant": s.participant, "group": s.group}
        text = encode(event, **{**keys, **fields})
        self.markers.push_sample([text], stamp)

    def session_started(self, session: SessionInfo) -> None:
        self.session = session
        info = self.lsl.StreamInfo(
            MARKER_STREAM,
            MARKER_TYPE,
            1,
            self.lsl.IRREGULAR_RATE,
            "string",
            f"haptic-study/{session.study}/{session.participant}",
        )
        info.desc().append_child_value("manufacturer", "haptic-study")
        self.markers = self.lsl.StreamOutlet(info)
        for task in session.tasks if self.sample_streams else ():
            self.outlets[task.name] = self._sample_outlet(task, ACQUISITION_RATE_HZ)
        if self.wait_for_consumers_s > 0:
            for outlet in (self.markers, *self.outlets.values()):
                outlet.wait_for_consumers(self.wait_for_consumers_s)
        self._mark(
            "session_start", self.lsl.local_clock(), driver=session.driver, pace=session.pace
        )

    def trial_started(self, trial: TrialInfo) -> None:
        self._t0_lsl = trial.clock_origin_s + self.offset_s
        self._mark("trial_start", self._t0_lsl, **trial.marker_fields())

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        if not len(rows):
            return
        outlet = self.outlets.get(trial.task.name)
        if outlet is None or (len(rows) > 1 and not self._checked.get(trial.task.name)):
            if len(rows) < 2:
                return  # two rows tell the rate
            rate_hz = round(1.0 / float(np.median(np.diff(rows[:, 0]))), 6)
            self._checked[trial.task.name] = True
            if outlet is None or outlet.get_info().nominal_srate() != rate_hz:
                _close_later([self.outlets.pop(trial.task.name, None)])
                outlet = self.outlets[trial.task.name] = self._sample_outlet(trial.task, rate_hz)
        t_last = float(rows[-1, 0])
        outlet.push_chunk(
            np.ascontiguousarray(rows, dtype=np.float64),
            self._t0_lsl + t_last / trial.clock_rate,
        )
        self.pushed += len(rows)

    def trial_ended(self, trial: TrialInfo, status: str, outcome: dict[str, Any]) -> None:
        t_end = outcome.get("t_s", outcome.get("completion_time_s", 0.0))
        stamp = self._t0_lsl + float(t_end or 0.0) / trial.clock_rate
        self._mark("trial_end", stamp, **trial.marker_fields(), status=status, **outcome)

    def event(self, kind: str, **fields: Any) -> None:
        self._mark(kind, self.lsl.local_clock(), **fields)

    def session_ended(self) -> None:
        self._mark("session_end", self.lsl.local_clock())
        outlets = [self.markers, *self.outlets.values()]
        self.markers, self.outlets = None, {}
        _close_later(outlets)

    # -- the trial's sample stream ------------------------------------------------------

    def _sample_outlet(self, task: Task, rate_hz: float) -> Any:
        """The sample outlet of `task` (see the module docstring)."""
        s = self.session
        info = self.lsl.StreamInfo(
            f"haptic-study {task.name}",
            SAMPLE_STREAM_TYPE,
            len(task.sample_columns),
            rate_hz,
            "double64",
            f"haptic-study/{s.study if s else ''}/{s.participant if s else ''}/{task.name}",
        )
        desc = info.desc()
        desc.append_child_value("manufacturer", "haptic-study")
        desc.append_child_value("hostname", platform.node())
        channels = desc.append_child("channels")
        for column in task.sample_columns:
            ch = channels.append_child("channel")
            ch.append_child_value("label", column.name)
            ch.append_child_value("unit", column.unit)
            ch.append_child_value("type", "time" if column.name == "t_s" else task.name)
            ch.append_child_value("description", column.description)
        regions = desc.append_child("regions")
        for region in task.regions:
            regions.append_child_value("region", region)
        return self.lsl.StreamOutlet(info, chunk_size=0, max_buffered=60)
