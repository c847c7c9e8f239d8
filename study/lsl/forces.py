"""A real follower's forces from an LSL stream: the lab's force-torque amplifier.

The design's `[sensors]` table with `source = "lsl"` names the stream (an LSL predicate)
and the channels holding the proximal reference force and the distal force, in N.
`LslForces` is then the follower's force source (`teleop_core.loop.follower_units.
ForceSource`): at each acquisition the loop takes the newest sample the inlet holds.
It lives in `study.lsl`, not beside the serial forces unit in `teleop_core`, because
pylsl is loaded only through `study.lsl.config.load_pylsl` (liblsl reads its network
configuration once, from the file `LSLAPICFG` names).

A stream that sends nothing new for `STALE_S`, or that is lost (the amplifier's program
ended), is a `HardwareError` that ends the trial as a silent or unplugged unit does.
"""

from __future__ import annotations

import math
import time
from typing import Any

from study.lsl.config import load_pylsl
from teleop_core.loop.follower_units import MAX_FORCE_N, ForceReading
from teleop_core.loop.hardware import HardwareError, UnitGone, UnitSilent

STALE_S = 0.1
"""How long the stream may send nothing before it is called silent, s (ten of the
loop's 100 Hz acquisitions: an amplifier at 100 Hz or faster sends in chunks of a few
samples)."""
RESOLVE_S = 2.0
"""How long the stream is looked for, and its first sample waited for, s."""


class LslForces:
    """The proximal and distal forces from channels of one LSL stream."""

    def __init__(
        self,
        predicate: str,
        proximal_channel: int,
        distal_channel: int,
        resolve_s: float = RESOLVE_S,
        stale_s: float = STALE_S,
    ) -> None:
        self.lsl = load_pylsl()
        self.predicate, self.stale_s = predicate, stale_s
        self.channels = (proximal_channel, distal_channel)
        found = self.lsl.resolve_bypred(predicate, 1, resolve_s)
        if not found:
            raise UnitSilent(f"no LSL stream {predicate} found within {resolve_s:g} s")
        self.inlet: Any = self.lsl.StreamInlet(found[0], max_buflen=2, recover=False)
        info = self.inlet.info(resolve_s)
        self.name = f"lsl {info.name()}"
        count = info.channel_count()
        if max(self.channels) >= count:
            self.inlet.close_stream()
            raise HardwareError(
                f"the LSL stream {predicate} has {count} channel(s); expected channels "
                f"{proximal_channel} and {distal_channel} (from 0)"
            )
        self.inlet.open_stream(resolve_s)
        self.corrupt_lines = 0
        self._last: ForceReading | None = None
        self._last_new = time.monotonic()
        self._first_wait_s = resolve_s

    def _pull(self) -> tuple[list[list[float]], list[float]]:
        try:
            return self.inlet.pull_chunk(timeout=0.0)
        except self.lsl.util.LostError:
            raise UnitGone(f"the LSL stream {self.predicate} is lost") from None

    def read(self) -> ForceReading:
        """The newest sample's forces; HardwareError when the stream is silent or lost."""
        values, stamps = self._pull()
        now = time.monotonic()
        if not stamps and self._last is None:
            # the first sample of the trial: wait for it (the stream has just opened)
            deadline = now + self._first_wait_s
            while not stamps and time.monotonic() < deadline:
                time.sleep(0.005)
                values, stamps = self._pull()
            now = time.monotonic()
        if stamps:
            sample = values[-1]
            forces = [float(sample[c]) for c in self.channels]
            if all(math.isfinite(f) and abs(f) <= MAX_FORCE_N for f in forces):
                self._last = ForceReading(float(stamps[-1]) * 1000.0, *forces)
                self._last_new = now
            else:  # never stored: the previous sample stands, and goes stale in time
                self.corrupt_lines += 1
        if self._last is None or now - self._last_new > self.stale_s:
            raise UnitSilent(
                f"no sample from the LSL stream {self.predicate} for "
                f"{(now - self._last_new) * 1000:.0f} ms"
            )
        return self._last

    def close(self) -> None:
        try:
            self.inlet.close_stream()
        except Exception:
            pass
