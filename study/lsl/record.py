"""Streams in: the design's other instruments recorded during each trial.

A `Recorder` is a session observer (`study.protocol.observer`). At the session's start
it resolves each of the design's predicates (`[lsl] record`, XPath as liblsl takes
them, e.g. `type='EMG'`) and opens an inlet on every stream found (one line and
nothing run if one finds none). During a trial it pulls what arrived at every step of
the loop (without waiting) and commits it at most a second at a time (`db.lsl_streams`),
each sample on the trial's clock:
`t_s = (lsl_time_s + time_correction_s - t0) * clock_rate`, `t0` the trial's start on
the LSL clock, while the loop keeps pace; where it falls behind the wall clock (a busy
machine), a sample's time is the loop's own progress at that moment instead,
interpolated between its steps (the runner reports each step as it is made), so that
an instrument's sample lines up with the trial's samples the loop was making then.
A stream that sends nothing for `gap_after_s` (or ten of its sample periods, whichever
is longer) is reported once (`notice`) and recorded as a gap, from its last sample
before to its first after (or the trial's end); the trial goes on.
Samples stamped before the trial's start or after its end are not kept.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np
from sqlalchemy import Engine

from db.lsl_streams import StreamMeta, StreamWriter, channel_names
from study.errors import StudyInputError
from study.lsl.clock import monotonic_to_lsl
from study.lsl.config import load_pylsl
from study.protocol.observer import SessionInfo, SessionObserver, TrialInfo

CHUNK_S = 1.0
"""Longest span of a stream's samples held before a commit, s (as the trial's own)."""
FORMATS = {1: "float32", 2: "double64", 3: "string", 4: "int32", 5: "int16", 6: "int8", 7: "int64"}
"""liblsl's channel format codes (`lsl_channel_format_t`)."""


def stream_channels(info: Any) -> list[dict[str, str]]:
    """[{"name", "unit", "type"}] of a pylsl `StreamInfo`'s channels (its XML desc)."""
    n = info.channel_count()
    labels: list[str | None] = []
    units: list[str] = []
    types: list[str] = []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty() and len(labels) < n:
        labels.append(ch.child_value("label") or None)
        units.append(ch.child_value("unit"))
        types.append(ch.child_value("type"))
        ch = ch.next_sibling()
    units += [""] * (n - len(units))
    types += [""] * (n - len(types))
    names = channel_names(labels, n)
    return [{"name": names[k], "unit": units[k], "type": types[k]} for k in range(n)]


@dataclass
class _Stream:
    inlet: Any
    meta: StreamMeta
    period_s: float
    writer: StreamWriter | None = None
    held_t: list[np.ndarray] = field(default_factory=list)
    held_trial_t: list[np.ndarray] = field(default_factory=list)
    held_v: list[Any] = field(default_factory=list)
    last_arrival: float = 0.0
    last_t: float | None = None
    gap_from: float | None = None
    gaps: list[list[float]] = field(default_factory=list)


class Recorder(SessionObserver):
    """Record the streams matching `predicates` with each trial (module docstring).

    Parameters
    ----------
    engine
        The study database.
    predicates
        LSL predicates, one per stream (or kind of stream) to record.
    notice
        Called with one line when a stream is lost or comes back.
    resolve_s
        How long to look for each predicate's stream at the session's start, s.
    gap_after_s
        Silence after which a stream is taken as lost, s.
    """

    def __init__(
        self,
        engine: Engine,
        predicates: tuple[str, ...],
        notice: Callable[[str], None] = lambda _: None,
        resolve_s: float = 2.0,
        gap_after_s: float = 0.5,
        pylsl: ModuleType | None = None,
    ) -> None:
        self.lsl = pylsl or load_pylsl()
        self.engine = engine
        self.predicates = predicates
        self.notice = notice
        self.resolve_s = resolve_s
        self.gap_after_s = gap_after_s
        self.offset_s = monotonic_to_lsl(self.lsl)
        self.streams: list[_Stream] = []
        self._t0 = 0.0
        self._rate = 1.0
        self._step_lsl: list[float] = []
        self._step_t: list[float] = []
        """When (LSL clock) the loop had made its samples up to which trial time."""

    def session_started(self, session: SessionInfo) -> None:
        if not session.tasks:  # no trial to record with (probes, a questionnaire)
            return
        if session.driver == "simulated" and session.pace is None:
            raise StudyInputError(
                "[lsl] record with an unpaced simulated session, whose clock runs ahead of "
                "the instruments'; expected --pace (e.g. --pace 1) or a person at the dial"
            )
        seen: set[str] = set()
        for predicate in self.predicates:
            found = self.lsl.resolve_bypred(predicate, 1, self.resolve_s)
            if not found:
                raise StudyInputError(
                    f"[lsl] record: no LSL stream matches {predicate!r} (looked for "
                    f"{self.resolve_s:g} s); expected that instrument's stream to be running"
                )
            for info in found:
                if info.uid() in seen:
                    continue
                seen.add(info.uid())
                self.streams.append(self._open(info))

    def _open(self, found: Any) -> _Stream:
        inlet = self.lsl.StreamInlet(found, max_buflen=360, recover=True)
        info = inlet.info(self.resolve_s)
        inlet.open_stream(self.resolve_s)
        correction = self._correction(inlet, 0.0, timeout_s=max(self.resolve_s, 1.0))
        rate = info.nominal_srate()
        meta = StreamMeta(
            name=info.name(),
            type=info.type(),
            channel_format=FORMATS.get(info.channel_format(), str(info.channel_format())),
            nominal_srate_hz=rate,
            channels=stream_channels(info),
            lsl_t0_s=0.0,
            time_correction_s=correction,
            source_id=info.source_id(),
            hostname=info.hostname(),
        )
        return _Stream(inlet, meta, 1.0 / rate if rate > 0 else 0.0)

    def _correction(self, inlet: Any, last: float, timeout_s: float = 0.2) -> float:
        """The inlet's time correction, s; the `last` estimate if the stream is lost."""
        try:
            return float(inlet.time_correction(timeout_s))
        except (self.lsl.util.TimeoutError, self.lsl.util.LostError):
            return last

    def trial_started(self, trial: TrialInfo) -> None:
        self._t0 = trial.clock_origin_s + self.offset_s
        self._rate = trial.clock_rate
        self._step_lsl, self._step_t = [], []
        for s in self.streams:
            s.meta.time_correction_s = self._correction(s.inlet, s.meta.time_correction_s)
            s.meta.lsl_t0_s, s.meta.clock_rate = self._t0, self._rate
            s.writer = StreamWriter.create(self.engine, trial.trial_id, s.meta)
            s.held_t, s.held_trial_t, s.held_v, s.gaps = [], [], [], []
            s.last_t, s.gap_from = None, None
            s.last_arrival = time.monotonic()

    def samples(self, trial: TrialInfo, rows: np.ndarray) -> None:
        now = time.monotonic()
        if len(rows):
            self._step_lsl.append(now + self.offset_s)
            self._step_t.append(float(rows[-1, 0]))
        for s in self.streams:
            self._pull(s, now, t_end=None)

    def trial_time(self, local_s: np.ndarray) -> np.ndarray:
        """Trial times of LSL times on this machine's clock (see the module docstring):
        the trial's clock, or the loop's progress where that is behind it."""
        ideal = (local_s - self._t0) * self._rate
        if not self._step_t:
            return ideal
        made = np.interp(local_s, self._step_lsl, self._step_t, left=np.inf, right=np.inf)
        return np.minimum(ideal, made)

    def _pull(self, s: _Stream, now: float, t_end: float | None) -> None:
        values, stamps = s.inlet.pull_chunk(timeout=0.0, max_samples=100_000)
        if stamps:
            t = np.asarray(stamps, dtype=np.float64)
            trial_t = self.trial_time(t + s.meta.time_correction_s)
            keep = trial_t >= 0
            if t_end is not None:
                keep &= trial_t <= t_end
            if keep.any():
                first = float(trial_t[keep][0])
                if s.gap_from is not None:
                    s.gaps.append([s.gap_from, first])
                    s.gap_from = None
                    self.notice(
                        f"LSL stream {s.meta.name} ({s.meta.type}) is back at t = {first:.2f} s"
                    )
                s.held_t.append(t[keep])
                s.held_trial_t.append(trial_t[keep])
                s.held_v.append([values[k] for k in np.flatnonzero(keep)])
                s.last_t = float(trial_t[keep][-1])
            s.last_arrival = now
        elif (
            s.period_s > 0
            and s.gap_from is None
            and now - s.last_arrival > max(self.gap_after_s, 10 * s.period_s)
        ):
            s.gap_from = s.last_t if s.last_t is not None else 0.0
            self.notice(
                f"LSL stream {s.meta.name} ({s.meta.type}) lost at t = {s.gap_from:.2f} s; "
                "recorded as a gap, the trial goes on"
            )
        held = sum(len(h) for h in s.held_t)
        if held and (t_end is not None or self._held_s(s) >= CHUNK_S):
            self._commit(s)

    def _held_s(self, s: _Stream) -> float:
        return float(s.held_trial_t[-1][-1] - s.held_trial_t[0][0])

    def _commit(self, s: _Stream) -> None:
        if s.writer is None:
            return
        t = np.concatenate(s.held_t)
        values = [v for block in s.held_v for v in block]
        s.writer.write(t, values, np.concatenate(s.held_trial_t))
        s.held_t, s.held_trial_t, s.held_v = [], [], []

    def trial_ended(self, trial: TrialInfo, status: str, outcome: dict[str, Any]) -> None:
        t_end = float(outcome.get("t_s", outcome.get("completion_time_s", 0.0)) or 0.0)
        # what the instruments stamped up to the trial's end may still be on its way
        deadline = self._t0 + t_end / self._rate + 0.05
        while self.lsl.local_clock() < deadline:
            time.sleep(0.005)
        now = time.monotonic()
        for s in self.streams:
            self._pull(s, now, t_end=t_end)
            if s.gap_from is not None:
                s.gaps.append([s.gap_from, t_end])
                s.gap_from = None
            if s.writer is not None:
                s.writer.close(s.gaps)
                s.writer = None

    def session_ended(self) -> None:
        for s in self.streams:
            s.inlet.close_stream()
        self.streams = []
