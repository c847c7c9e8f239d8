"""Command-to-state round trip against the firmware's host build, at the host's 100 Hz.

    python benchmarks/unit_round_trip.py --commands 3000 \
        --json benchmarks/results/unit_round_trip.json

It builds `firmware/host` (CMake and the system compiler) into a temporary folder,
starts a dial unit and a drive unit on their pseudo-terminals, and sends each one
command every 10 ms as a session does (the dial a q-current, a 1 Hz sine of 2 mA; the
drive a speed, a 0.5 Hz sine of 5 rad/s), timing each from the write of the command to
the parsed state line (`Esp32Unit.set_current` / `set_speed`, the calls the session's
driver makes). It reports the median, 95th percentile and largest round trip, the
commands sent on schedule and the corrupt lines, per unit.

The units are the firmware's host build: the firmware's own parser and control cycle on
a simulated motor, so the figures are the host's side of the link and the firmware's
reply path; a real unit's USB serial bridge (a CP2102, a CH340) adds its own latency,
which `study hardware check` measures on the device.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from teleop_core.loop.hardware import UPDATE_PERIOD_S, Esp32Unit
from teleop_core.loop.host_unit import HostUnit, build_host_firmware

TARGET_MEDIAN_MS = 2.0


def run_unit(build: Path, role: str, commands: int) -> dict[str, object]:
    """Send `commands` commands at 100 Hz to a host-built unit of `role`; the figures."""
    with HostUnit(build, role) as host:
        unit = Esp32Unit(host.port, role)
        try:
            round_trips_s, late = _drive(unit, role, commands)
        finally:
            unit.close()
        corrupt = unit.corrupt_lines
        firmware = unit.firmware
    ms = np.asarray(round_trips_s) * 1000.0
    return {
        "firmware": firmware,
        "commands": commands,
        "round_trip_ms": {
            "median": float(np.median(ms)),
            "p95": float(np.percentile(ms, 95)),
            "p99": float(np.percentile(ms, 99)),
            "max": float(ms.max()),
            "mean": float(ms.mean()),
        },
        "over_2ms_fraction": float(np.mean(ms > TARGET_MEDIAN_MS)),
        "late_updates": late,
        "corrupt_lines": corrupt,
        "target_median_ms": TARGET_MEDIAN_MS,
        "met": bool(np.median(ms) < TARGET_MEDIAN_MS),
    }


def _drive(unit: Esp32Unit, role: str, commands: int) -> tuple[list[float], int]:
    """The round trips (s) and how many updates started more than a period late."""
    round_trips: list[float] = []
    late = 0
    start = time.monotonic()
    for k in range(commands):
        due = start + k * UPDATE_PERIOD_S
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        elif -wait > UPDATE_PERIOD_S:
            late += 1
        t_s = k * UPDATE_PERIOD_S
        sent = time.perf_counter()
        if role == "dial":
            unit.set_current(0.002 * math.sin(2 * math.pi * 1.0 * t_s))  # A
        else:
            unit.set_speed(5.0 * math.sin(2 * math.pi * 0.5 * t_s))  # rad/s
        round_trips.append(time.perf_counter() - sent)
        if k % 500 == 499:
            print(f"  {role}: {k + 1}/{commands} commands", file=sys.stderr, flush=True)
    return round_trips, late


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commands", type=int, default=3000, help="Per unit (100 per s).")
    parser.add_argument("--json", type=Path, default=None, help="Write the figures here.")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="firmware-host-") as folder:
        print("building the firmware's host build", file=sys.stderr, flush=True)
        build = build_host_firmware(Path(folder))
        result = {
            "data": "simulated: the firmware's host build on a pseudo-terminal, no hardware",
            "command": "python benchmarks/unit_round_trip.py --commands "
            f"{args.commands} --json benchmarks/results/unit_round_trip.json",
            "rate_hz": 1.0 / UPDATE_PERIOD_S,
            "machine": {
                "cpus": os.cpu_count(),
                "load_average_1min_before": os.getloadavg()[0],
                "python": platform.python_version(),
            },
            "dial": run_unit(build, "dial", args.commands),
            "drive": run_unit(build, "drive", args.commands),
        }
    result["machine"]["load_average_1min_after"] = os.getloadavg()[0]  # type: ignore[index]
    text = json.dumps(result, indent=2)
    if args.json is not None:
        args.json.write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
