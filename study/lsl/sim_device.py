"""A simulated instrument on the Lab Streaming Layer, for trying the recorder and for
`study bench lsl`: `python -m study.lsl.sim_device NAME TYPE RATE_HZ SECONDS LOG`.

Streams two channels at RATE_HZ for SECONDS (SIMULATED data, no device behind it):
`index` (the sample's number) and `made_s` (`time.monotonic()` when it was made), each
sample pushed without a stamp so that liblsl stamps it at the push, as most vendors'
drivers do; then writes `index made_s` per sample to LOG. Refuses to run unless
`LSLAPICFG` names a liblsl configuration (`study.lsl.config`).
"""

from __future__ import annotations

import sys
import time

from study.lsl.config import load_pylsl


def stream(name: str, kind: str, rate_hz: float, seconds: float, log: str) -> None:
    pylsl = load_pylsl()
    info = pylsl.StreamInfo(name, kind, 2, rate_hz, "double64", f"simulated-{name}")
    desc = info.desc()
    desc.append_child_value("manufacturer", "haptic-study (SIMULATED instrument)")
    channels = desc.append_child("channels")
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
    del outlet
    with open(log, "w") as out:
        out.writelines(f"{k} {m!r}\n" for k, m in enumerate(made))


if __name__ == "__main__":
    stream(sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), sys.argv[5])
