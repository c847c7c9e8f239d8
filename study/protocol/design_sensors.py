"""The design's `[sensors]` table: where a session with a real follower reads its forces.

With a drive unit in the loop (`study run --driver hardware --drive-port ...`) the
phantom is the physical one, and its forces (the proximal reference at the insertion
point, the distal force under the tip) come from the lab's sensors, not from a model.
The table names them; it lives apart from `design` because only that session reads it.
`predicate_problem`, the check of an LSL stream predicate, is here too: `design`'s
`[lsl]` table uses it as well, and `design` imports this module, not the reverse.

    [sensors]
    source = "serial"        # a forces unit speaking the units' protocol
    port = "/dev/ttyUSB2"    # its serial port (a device path or a pyserial URL)

    [sensors]
    source = "lsl"           # the lab's force-torque amplifier as an LSL stream
    stream = "name='FT'"     # the LSL predicate that finds it
    proximal_channel = 0     # its channels (from 0) holding the two forces, N
    distal_channel = 1
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from study.errors import StudyInputError

SOURCES = ("serial", "lsl")
"""Where the forces can come from."""
MAX_TEXT_CHARS = 500
MAX_CHANNEL = 1023
KEYS = {
    "serial": ("source", "port"),
    "lsl": ("source", "stream", "proximal_channel", "distal_channel"),
}


@dataclass(frozen=True)
class SensorSettings:
    """The `[sensors]` table; `source` None: the design names no sensors."""

    source: str | None = None
    """`serial`: a forces unit on `port` (`teleop_core.loop.follower_units.ForceUnit`);
    `lsl`: the channels of an LSL stream (`study.lsl.forces`)."""
    port: str = ""
    """The forces unit's serial port (`serial`)."""
    stream: str = ""
    """The LSL predicate of the amplifier's stream, e.g. ``name='FT'`` (`lsl`)."""
    proximal_channel: int = 0
    """The stream's channel (from 0) holding the proximal reference force, N (`lsl`)."""
    distal_channel: int = 1
    """The stream's channel (from 0) holding the distal force, N (`lsl`)."""

    @property
    def where(self) -> str:
        """The source in a few words, for a message."""
        if self.source == "lsl":
            return f"the LSL stream {self.stream}"
        return f"the forces unit on {self.port}"

    def to_dict(self) -> dict[str, Any]:
        if self.source is None:
            return {}
        if self.source == "serial":
            return {"source": self.source, "port": self.port}
        return {
            "source": self.source,
            "stream": self.stream,
            "proximal_channel": self.proximal_channel,
            "distal_channel": self.distal_channel,
        }


def _text(table: dict[str, Any], key: str, source: str, example: str) -> str:
    value = table.get(key)
    if not (
        isinstance(value, str)
        and value.strip()
        and len(value) <= MAX_TEXT_CHARS
        and value.isprintable()
    ):
        raise StudyInputError(f"{source}: sensors.{key} = {value!r}; expected {example}")
    return value


def _channel(table: dict[str, Any], key: str, default: int, source: str) -> int:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_CHANNEL:
        raise StudyInputError(
            f"{source}: sensors.{key} = {value!r}; expected a channel number, 0 to {MAX_CHANNEL}"
        )
    return value


def sensor_settings(table: dict[str, Any], source: str) -> SensorSettings:
    """The `[sensors]` table of a parsed design; StudyInputError naming a bad value."""
    if not table:
        return SensorSettings()
    kind = table.get("source", "serial")
    if kind not in SOURCES:
        raise StudyInputError(
            f"{source}: sensors.source = {kind!r}; expected one of {', '.join(SOURCES)}"
        )
    known = KEYS[kind]
    for key in table:
        if key not in known:
            raise StudyInputError(
                f"{source}: unknown key sensors.{key} for source {kind!r}; expected one of "
                f"{', '.join(known)}"
            )
    if kind == "serial":
        port = _text(
            table, "port", source, 'the forces unit\'s serial port in quotes, e.g. "/dev/ttyUSB2"'
        )
        return SensorSettings(kind, port=port)
    stream = _text(table, "stream", source, "an LSL predicate in quotes, e.g. \"name='FT'\"")
    problem = predicate_problem(stream)
    if problem:
        raise StudyInputError(
            f"{source}: sensors.stream {stream!r} has {problem}; expected an LSL predicate "
            "such as name='FT'"
        )
    proximal = _channel(table, "proximal_channel", 0, source)
    distal = _channel(table, "distal_channel", 1, source)
    if proximal == distal:
        raise StudyInputError(
            f"{source}: sensors.distal_channel = {distal}; expected a channel other than "
            f"sensors.proximal_channel ({proximal})"
        )
    return SensorSettings(kind, stream=stream, proximal_channel=proximal, distal_channel=distal)


def predicate_problem(query: str) -> str | None:
    """What is unbalanced in an LSL stream query (liblsl's XPath 1.0 predicate, which
    would fail only when the session starts recording), or None."""
    depth, quote = 0, None
    for c in query:
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
            if depth < 0:
                return f"a {c!r} without its opening bracket"
    if quote:
        return f"an unclosed {quote} quote"
    if depth:
        return "an unclosed bracket"
    return None
