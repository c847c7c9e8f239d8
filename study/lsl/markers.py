"""The project's LSL markers: one JSON object per marker, recognisable in any recording.

Every marker the session publishes is a JSON object with `"haptic_study": 1`, an
`event` and the session's keys (`participant`, `group`, `study`); a trial's markers add
its keys (`task`, `condition`, `block`, `trial`, `practice`, `attempt`, `trial_id`,
`clock_rate`) and, at its end, the outcome. Events: `session_start`, `trial_start`,
`trial_end` (`status`: completed, stopped or interrupted; `success` and the measures
when completed, and on a physical phantom `end`: button, experimenter or time_limit),
`probe`, `questionnaire`, `session_end`. The stream: name
`MARKER_STREAM`, type `Markers`, one string channel, irregular rate; each marker is
stamped on the LSL clock at the moment it names (a trial's start at its t = 0).
JSON rather than a bespoke string: PsychoPy, LabRecorder and any XDF reader pass it
through unchanged, and `parse` needs nothing but the standard library.
"""

from __future__ import annotations

import json
import math
from typing import Any

MARKER_STREAM = "haptic-study markers"
MARKER_TYPE = "Markers"
SAMPLE_STREAM_TYPE = "haptic-study samples"
"""The type of the per-trial sample streams (named `haptic-study <task>`)."""
KEY = "haptic_study"
VERSION = 1
EVENTS = (
    "session_start",
    "trial_start",
    "trial_end",
    "probe",
    "questionnaire",
    "session_end",
)


def _plain(value: Any) -> Any:
    """A JSON-safe value (numpy scalars as Python numbers, non-finite floats as None)."""
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def encode(event: str, **fields: Any) -> str:
    """One marker's text."""
    if event not in EVENTS:
        raise ValueError(f"marker event {event!r}; expected one of {', '.join(EVENTS)}")
    body = {KEY: VERSION, "event": event, **{k: _plain(v) for k, v in fields.items()}}
    return json.dumps(body, separators=(",", ":"), sort_keys=False)


def parse(text: str) -> dict[str, Any] | None:
    """The fields of a project marker, or None for any other marker text."""
    if not text.startswith("{"):
        return None
    try:
        body = json.loads(text)
    except (ValueError, RecursionError):  # RecursionError: nested too deep to be ours
        return None
    if not isinstance(body, dict) or body.get(KEY) != VERSION or body.get("event") not in EVENTS:
        return None
    return body
