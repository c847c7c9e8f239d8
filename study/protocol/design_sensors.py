"""The design's `[sensors]` table: where a session with a real follower reads its forces.

With a drive unit in the loop (`study run --driver hardware --drive-port ...`) the
phantom is the physical one, and its forces (the proximal reference at the insertion
point, the distal force under the tip) come from the lab's sensors, not from a model.
The table names them; it lives apart from `design` because only that session reads it.

    [sensors]
    source = "serial"        # a forces unit speaking the units' protocol
    port = "/dev/ttyUSB2"    # its serial port (a device path or a pyserial URL)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from study.errors import StudyInputError

SOURCES = ("serial",)
"""Where the forces can come from."""
MAX_PORT_CHARS = 200


@dataclass(frozen=True)
class SensorSettings:
    """The `[sensors]` table; `source` None: the design names no sensors."""

    source: str | None = None
    """`serial`: a forces unit on `port` (`teleop_core.loop.follower_units.ForceUnit`)."""
    port: str = ""
    """The forces unit's serial port."""

    def to_dict(self) -> dict[str, Any]:
        return {} if self.source is None else {"source": self.source, "port": self.port}


def sensor_settings(table: dict[str, Any], source: str) -> SensorSettings:
    """The `[sensors]` table of a parsed design; StudyInputError naming a bad value."""
    if not table:
        return SensorSettings()
    known = ("source", "port")
    for key in table:
        if key not in known:
            raise StudyInputError(
                f"{source}: unknown key sensors.{key}; expected one of {', '.join(known)}"
            )
    kind = table.get("source", "serial")
    if kind not in SOURCES:
        raise StudyInputError(
            f"{source}: sensors.source = {kind!r}; expected one of {', '.join(SOURCES)}"
        )
    port = table.get("port")
    if not (
        isinstance(port, str)
        and port.strip()
        and len(port) <= MAX_PORT_CHARS
        and port.isprintable()
    ):
        raise StudyInputError(
            f"{source}: sensors.port = {port!r}; expected the forces unit's serial port in "
            'quotes, e.g. "/dev/ttyUSB2"'
        )
    return SensorSettings(kind, port)
