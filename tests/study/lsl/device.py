"""An outside instrument, as a vendor's driver would publish it: `python device.py NAME
TYPE RATE_HZ SECONDS LOG`.

Streams two channels at RATE_HZ for SECONDS: `index` (the sample's number from 0) and
`made_s` (`time.monotonic()` when the sample was made); each sample is pushed without a
time stamp, so liblsl stamps it with its own clock at the push, as most vendors do.
Writes `index made_s` per sample to LOG when it ends. Run with the test suite's
LSLAPICFG in its environment (inherited), never without. Written with pylsl alone, as a
vendor would, not with `study.lsl` (whose `sim_device` serves the bench).
"""

from __future__ import annotations

import os
import sys
import time

if not os.environ.get("LSLAPICFG"):
    sys.exit("LSLAPICFG is not set; the test device never runs on liblsl's defaults")

import pylsl  # after the check above


def main(name: str, kind: str, rate_hz: float, seconds: float, log: str) -> None:
    info = pylsl.StreamInfo(name, kind, 2, rate_hz, "double64", f"device-{name}")
    channels = info.desc().append_child("channels")
    for label, unit in (("index", "count"), ("made_s", "s")):
        ch = channels.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", unit)
    outlet = pylsl.StreamOutlet(info)
    made: list[float] = []
    start = time.monotonic()
    period = 1.0 / rate_hz
    print("ready", flush=True)
    while (now := time.monotonic()) < start + seconds:
        while start + len(made) * period <= now:
            made_s = time.monotonic()
            outlet.push_sample([float(len(made)), made_s])
            made.append(made_s)
        time.sleep(period / 4)
    del outlet  # the stream ends: an inlet sees it lost
    with open(log, "w") as out:
        out.writelines(f"{k} {m!r}\n" for k, m in enumerate(made))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), sys.argv[5])
