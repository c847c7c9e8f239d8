"""XDF in: a LabRecorder recording's streams stored with the trials its markers name.

LabRecorder writes every stream it recorded into one XDF file (the format: a magic
`XDF:`, then chunks of `[NumLengthBytes][Length][Tag][Content]`; tag 2 a stream's
header, 3 its samples, 4 a clock offset, 6 its footer). `import_xdf` reads it with
pyxdf (which also puts every stream on the recorder's clock from the clock offsets),
finds the trials by the project's markers (`study.lsl.markers`: each trial's
`trial_start` and `trial_end`), and stores, for each trial, every other stream's
samples stamped between the two (the project's own sample streams are already in the
database). Each sample's time on the trial's clock is its synchronised stamp minus the
`trial_start` marker's, times the trial's clock rate.

Refused with one line, nothing stored: a file that is not XDF; a truncated one (a chunk
running past the end of the file, or a stream without the footer LabRecorder writes
when it stops); one pyxdf can read only in part; a stream with a time stamp, a clock
offset or a nominal rate that is not a finite number; one without the project's markers;
a marker field that is missing or not of its type (`TRIAL_FIELDS`), a trial's end that
disagrees with its start; markers of another study, or naming a trial the database does
not have; a trial whose streams were imported already.
pyxdf reads damaged files as far as it can; the structural check is done here, before,
for that reason.
"""

from __future__ import annotations

import json
import logging
import math
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import Engine, insert, select
from sqlalchemy.orm import Session

from db.lsl_streams import StreamMeta, channel_names, encode_chunk, stream_row
from db.models.lsl import LslChunk, LslStream
from db.models.study import Participant
from db.models.trial import Trial
from study.errors import StudyInputError
from study.lsl.markers import SAMPLE_STREAM_TYPE, parse
from study.protocol.roster import load_study
from teleop_core.progress import Progress, no_progress

MAGIC = b"XDF:"
CHUNK_S = 1.0
"""Longest span of trial time in one stored chunk, s."""


class XdfInputError(StudyInputError):
    """A recording that cannot be imported; the message says why."""


def check_structure(path: Path) -> None:
    """Refuse a file that is not XDF or that was cut short (see the module docstring)."""
    size = path.stat().st_size
    with path.open("rb") as f:
        if f.read(4) != MAGIC:
            raise XdfInputError(
                f"{path} is not an XDF file (no 'XDF:' at its start); "
                "expected a LabRecorder recording"
            )
        headers: set[int] = set()
        footers: set[int] = set()
        k = 0
        while True:
            at = f.tell()
            width = f.read(1)
            if not width:
                break
            k += 1
            nbytes = {1: 1, 4: 4, 8: 8}.get(width[0])
            raw = f.read(nbytes or 0)
            if nbytes is None or len(raw) < nbytes:
                raise _truncated(path, k, at, size)
            length = int.from_bytes(raw, "little")
            body = f.tell()
            if length < 2 or body + length > size:
                raise _truncated(path, k, at, size)
            tag = struct.unpack("<H", f.read(2))[0]
            if tag in (2, 6):
                stream_id = struct.unpack("<I", f.read(4))[0]
                (headers if tag == 2 else footers).add(stream_id)
            f.seek(body + length)
    missing = sorted(headers - footers)
    if missing:
        raise XdfInputError(
            f"{path} is truncated: stream {missing[0]} has no footer (the recording did not "
            "end cleanly); expected a complete LabRecorder recording"
        )


def _truncated(path: Path, k: int, at: int, size: int) -> XdfInputError:
    return XdfInputError(
        f"{path} is truncated: chunk {k} at byte {at} runs past the end of the file "
        f"({size} bytes); expected a complete LabRecorder recording"
    )


MAX_INDEX = 1_000_000
"""Above any block, trial or attempt number a study reaches (and within SQLite's integers)."""
MAX_CLOCK_RATE = 1e6
"""Trial seconds per wall second: `study run --pace` is far below."""


@dataclass(frozen=True)
class MarkedTrial:
    """A trial as the markers give it: its keys, and its start and end on the recording's
    clock. Built by `marked_trials` only from markers whose fields were all checked."""

    start: dict[str, Any]
    start_s: float
    end_s: float

    @property
    def key(self) -> tuple[str, int, bool, int, int]:
        m = self.start
        return (m["participant"], m["block"], m["practice"], m["trial"], m["attempt"])

    @property
    def clock_rate(self) -> float:
        return float(self.start["clock_rate"])


def _whole(value: Any, low: int, high: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and low <= value <= high


TRIAL_FIELDS: dict[str, tuple[str, Any]] = {
    "study": ("a study name", lambda v: isinstance(v, str) and 0 < len(v) <= 200),
    "participant": (
        "a participant code",
        lambda v: isinstance(v, str) and 0 < len(v) <= 32 and v.isprintable(),
    ),
    "trial_id": (f"a whole number from 1 to {2**63 - 1}", lambda v: _whole(v, 1, 2**63 - 1)),
    "block": (f"a whole number from 0 to {MAX_INDEX}", lambda v: _whole(v, 0, MAX_INDEX)),
    "trial": (f"a whole number from 0 to {MAX_INDEX}", lambda v: _whole(v, 0, MAX_INDEX)),
    "attempt": (f"a whole number from 0 to {MAX_INDEX}", lambda v: _whole(v, 0, MAX_INDEX)),
    "practice": ("true or false", lambda v: isinstance(v, bool)),
    "clock_rate": (
        f"a number above 0 and at most {MAX_CLOCK_RATE:g}",
        lambda v: (
            isinstance(v, int | float)
            and not isinstance(v, bool)
            and math.isfinite(v)
            and 0 < v <= MAX_CLOCK_RATE
        ),
    ),
}
"""A trial's marker fields that the import reads, each with what it must be (JSON's own
types: `"practice": "no"` or `"trial": 1.5` is refused, not read as something else).
`study run` writes them into both the `trial_start` and the `trial_end` marker, and the
two must agree."""


def _check_fields(path: Path, t: float, marker: dict[str, Any]) -> None:
    event = marker["event"]
    for name, (expected, ok) in TRIAL_FIELDS.items():
        if name not in marker:
            raise XdfInputError(
                f"{path}: the {event} marker at {t:.3f} s has no field {name!r}; expected "
                f"{expected} (a marker `study run` publishes)"
            )
        if not ok(marker[name]):
            raise XdfInputError(
                f"{path}: the {event} marker at {t:.3f} s has {name} = "
                f"{_shown(marker[name])}; expected {expected}"
            )


def _shown(value: Any) -> str:

    text = json.dumps(value, ensure_ascii=True)
    return text if len(text) <= 40 else text[:37] + "..."


def marked_trials(
    streams: list[dict[str, Any]], path: Path = Path("recording")
) -> tuple[list[MarkedTrial], set[int]]:
    """The trials the project's markers delimit, and the indices of the marker streams.

    Every `trial_start` and `trial_end` is checked before any is used (`TRIAL_FIELDS`);
    a trial started or ended twice, ended without its start, or whose end names other
    keys than its start makes the recording inconsistent and is refused. A start without
    an end is a trial the session did not finish (a crash): it has no span to store
    samples of, and is left out.
    """
    found: list[tuple[float, dict[str, Any]]] = []
    marker_streams: set[int] = set()
    for i, stream in enumerate(streams):
        if _info(stream, "channel_format") != "string":
            continue
        parsed = [
            (float(t), parse(str(v[0]) if len(v) else ""))
            for t, v in zip(stream["time_stamps"], stream["time_series"], strict=True)
        ]
        ours = [(t, m) for t, m in parsed if m is not None]
        if ours:
            marker_streams.add(i)
            found += ours
    found.sort(key=lambda tm: tm[0])
    trials, starts, ended = [], {}, set()
    for t, m in found:
        if m["event"] not in ("trial_start", "trial_end"):
            continue
        _check_fields(path, t, m)
        tid = m["trial_id"]
        if m["event"] == "trial_start":
            if tid in starts:
                raise _inconsistent(path, t, f"a second trial_start of trial_id {tid}")
            starts[tid] = (t, m)
            continue
        if tid not in starts:
            raise _inconsistent(path, t, f"a trial_end of trial_id {tid} without its start")
        if tid in ended:
            raise _inconsistent(path, t, f"a second trial_end of trial_id {tid}")
        ended.add(tid)
        start_t, start = starts[tid]
        differs = next((k for k in TRIAL_FIELDS if m[k] != start[k]), None)
        if differs is not None:
            raise _inconsistent(
                path,
                t,
                f"a trial_end of trial_id {tid} with {differs} = {_shown(m[differs])} where "
                f"its trial_start has {_shown(start[differs])}",
            )
        trials.append(MarkedTrial(start, start_t, t))
    return trials, marker_streams


def _inconsistent(path: Path, t: float, what: str) -> XdfInputError:
    return XdfInputError(
        f"{path} is inconsistent: {what} at {t:.3f} s; expected each trial's start and end "
        "marker once, in that order"
    )


def _info(stream: dict[str, Any], key: str, default: str = "") -> str:
    value = stream["info"].get(key, [default])
    return str(value[0] if isinstance(value, list) and value else value or default)


def _channels(stream: dict[str, Any], n: int) -> list[dict[str, str]]:
    labels: list[str | None] = []
    units: list[str] = []
    types: list[str] = []
    try:
        for ch in stream["info"]["desc"][0]["channels"][0]["channel"]:
            labels.append((ch.get("label") or [None])[0])
            units.append((ch.get("unit") or [""])[0] or "")
            types.append((ch.get("type") or [""])[0] or "")
    except (KeyError, IndexError, TypeError):
        pass
    units += [""] * (n - len(units))
    types += [""] * (n - len(types))
    names = channel_names(labels, n)
    return [{"name": names[k], "unit": units[k], "type": types[k]} for k in range(n)]


class _Collected(logging.Handler):
    """pyxdf's log records, kept instead of printed (it logs the errors of a stream it
    cannot parse, traceback and all, and goes on with what it read)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


def _load(path: Path) -> list[dict[str, Any]]:
    """The recording's streams as pyxdf reads them, or one line if pyxdf could read only
    part of it: an error it logged (a stream whose data do not fit its header), or a
    stream with fewer samples than its footer counts."""
    # lazy: pyxdf costs 5 ms at start-up
    import pyxdf

    logger = logging.getLogger("pyxdf")
    collected = _Collected()
    level, propagate = logger.level, logger.propagate
    logger.addHandler(collected)
    logger.setLevel(logging.WARNING)
    logger.propagate = False
    try:
        # numpy's warnings too: a nan clock offset makes pyxdf's fit warn on every line
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            streams, _ = pyxdf.load_xdf(str(path), dejitter_timestamps=False)
    except Exception as exc:  # pyxdf raises what its parsers raise
        raise XdfInputError(
            f"{path} could not be read as XDF ({_first_line(exc)}); expected a LabRecorder "
            "recording"
        ) from None
    finally:
        logger.removeHandler(collected)
        logger.setLevel(level)
        logger.propagate = propagate
    errors = [r for r in collected.records if r.levelno >= logging.ERROR]
    if errors:
        raise XdfInputError(
            f"{path} could be read only in part (pyxdf: {_first_line(errors[0].getMessage())}); "
            "expected a consistent recording, each stream's data as its header declares "
            "(nothing was stored)"
        )
    for stream in streams:
        _check_numbers(path, stream)
        counted = _footer_count(stream)
        read = len(stream.get("time_stamps", ()))
        if counted is not None and counted != read:
            raise XdfInputError(
                f"{path}: stream {_info(stream, 'name')!r} has {read} samples where its "
                f"footer counts {counted}; expected a complete, consistent recording "
                "(nothing was stored)"
            )
    return list(streams)


def _check_numbers(path: Path, stream: dict[str, Any]) -> None:
    """XdfInputError for a stream whose time stamps, clock offsets or nominal rate are not
    finite numbers (pyxdf reads `nan` and `inf` as numbers; nothing a recorder writes)."""
    name = _info(stream, "name")
    for what, values in (  # the offsets first: a bad one makes the synchronised stamps nan
        ("clock offset", stream.get("clock_values", ())),
        ("clock offset's time", stream.get("clock_times", ())),
        ("sample time stamp", stream.get("time_stamps", ())),
    ):
        numbers = np.asarray(values, dtype=np.float64).ravel()
        bad = np.flatnonzero(~np.isfinite(numbers))
        if len(bad):
            raise XdfInputError(
                f"{path}: stream {name!r} has {what} number {bad[0] + 1} = {numbers[bad[0]]}; "
                "expected finite numbers of seconds (nothing was stored)"
            )
    text = _info(stream, "nominal_srate", "0")
    try:
        rate = float(text)
    except ValueError:
        rate = math.nan
    if not (math.isfinite(rate) and rate >= 0):
        raise XdfInputError(
            f"{path}: stream {name!r} has nominal_srate {text!r}; expected a rate in Hz of "
            "0 (irregular) or more (nothing was stored)"
        )


def _footer_count(stream: dict[str, Any]) -> int | None:
    try:
        text = stream["footer"]["info"]["sample_count"][0]
    except (KeyError, IndexError, TypeError):
        return None
    return int(text) if isinstance(text, str) and text.strip().isdigit() else None


def _first_line(value: object) -> str:
    text = str(value).strip()
    return text.splitlines()[0] if text else type(value).__name__


@dataclass
class ImportResult:
    trials: int
    streams: int
    samples: int


def import_xdf(engine: Engine, path: Path, progress: Progress = no_progress) -> ImportResult:
    """Store the recording's streams with the trials its markers name (module docstring)."""
    check_structure(path)
    progress(f"reading {path.name}")
    streams = _load(path)
    trials, marker_streams = marked_trials(streams, path)
    if not trials:
        raise XdfInputError(
            f"{path} has no haptic-study trial markers; expected a recording made while "
            "`study run` published them ([lsl] publish = true, or --lsl)"
        )
    others = [
        i
        for i in range(len(streams))
        if i not in marker_streams and _info(streams[i], "type") != SAMPLE_STREAM_TYPE
    ]
    with Session(engine) as session:
        study, _ = load_study(session)
        other = next((t.start["study"] for t in trials if t.start["study"] != study.name), None)
        if other is not None:
            raise XdfInputError(
                f"{path}: the markers are of study {other!r}; expected this database's "
                f"study {study.name!r}"
            )
        ids = [_trial_id(session, study.id, path, t) for t in trials]
        for trial_id in ids:
            taken = session.scalars(select(LslStream.name).where(LslStream.trial_id == trial_id))
            names = {_info(streams[i], "name") for i in others}
            again = sorted(names & set(taken))
            if again:
                raise XdfInputError(
                    f"{path}: stream {again[0]!r} of trial {trial_id} is stored already; "
                    "expected a recording not yet imported"
                )
    progress(f"storing {len(others)} streams of {len(trials)} trials")
    n_streams = n_samples = 0
    with engine.begin() as conn:  # all or nothing
        for trial, trial_id in zip(trials, ids, strict=True):
            for i in others:
                stored = _store(conn, streams[i], trial, trial_id)
                n_streams += stored > 0
                n_samples += stored
    return ImportResult(len(trials), n_streams, n_samples)


def _trial_id(session: Session, study_id: int, path: Path, trial: MarkedTrial) -> int:
    code, block, practice, index, attempt = trial.key
    found = session.scalar(
        select(Trial.id)
        .join(Participant)
        .where(
            Participant.study_id == study_id,
            Participant.code == code,
            Trial.block_index == block,
            Trial.practice == practice,
            Trial.trial_index == index,
            Trial.attempt == attempt,
        )
    )
    if found is None:
        kind = "practice trial" if practice else "trial"
        raise XdfInputError(
            f"{path}: the markers name {code} block {block} {kind} {index + 1} attempt "
            f"{attempt}, which this database does not have; expected the study's database"
        )
    return found


def _store(conn: Any, stream: dict[str, Any], trial: MarkedTrial, trial_id: int) -> int:
    stamps = np.asarray(stream["time_stamps"], dtype=np.float64)
    inside = np.flatnonzero((stamps >= trial.start_s) & (stamps <= trial.end_s))
    fmt = _info(stream, "channel_format")
    n_channels = int(_info(stream, "channel_count", "0"))
    rate = trial.clock_rate
    offsets = np.asarray(stream.get("clock_values", []), dtype=np.float64)
    correction = float(np.median(offsets)) if len(offsets) else 0.0
    meta = StreamMeta(
        name=_info(stream, "name"),
        type=_info(stream, "type"),
        channel_format=fmt,
        nominal_srate_hz=float(_info(stream, "nominal_srate", "0")),
        channels=_channels(stream, n_channels),
        lsl_t0_s=trial.start_s,
        time_correction_s=correction,
        clock_rate=rate,
        source_id=_info(stream, "source_id"),
        hostname=_info(stream, "hostname"),
        origin="xdf",
    )
    stream_id = conn.execute(
        insert(LslStream).returning(LslStream.id),
        {"trial_id": trial_id, "gaps": [], "n_samples": len(inside), **stream_row(meta)},
    ).scalar_one()
    if not len(inside):
        return 0
    series = stream["time_series"]
    t_s = (stamps[inside] - trial.start_s) * rate
    start = 0
    while start < len(inside):
        stop = start + int(np.searchsorted(t_s[start:], t_s[start] + CHUNK_S, side="left"))
        stop = max(stop, start + 1)
        rows = inside[start:stop]
        values = [series[k] for k in rows] if meta.is_string else np.asarray(series)[rows]
        conn.execute(
            insert(LslChunk),
            {
                "stream_id": stream_id,
                "first_seq": start,
                **encode_chunk(meta, stamps[rows] - correction, values, t_s[start:stop]),
            },
        )
        start = stop
    return len(inside)
