"""The firmware's host build as a unit on a pseudo-terminal: firmware in the loop.

`firmware/` holds the units' firmware; its protocol and control code is plain C++ that
also builds on the host (`firmware/host`, CMake and the system compiler) against a
simulated motor (the AS5600's 12-bit angle, the INA240's noise, the 2804's torque
constant). `build_host_firmware` compiles it; `HostUnit` starts one unit as a process
that serves the protocol on a pty and reports the pty's path, which `HardwareDriver`
and `study hardware check` open as they open `/dev/ttyUSB0`. The same firmware source
runs on the ESP32, so what the host's side of the protocol meets here is the
firmware's own behaviour (its parser, its `E` lines, its watchdog), not a model of it
(`teleop_core.loop.emulator` is the pure-Python stand-in).

A unit can be unplugged (`unplug`: the process is killed and its pty goes away),
frozen (`freeze` / `thaw`: it stops answering, as a hung unit does) and started again;
a dial's button can be pressed (`press`).
Data from it are simulated: its firmware version ends in `-host`.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from pathlib import Path

FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware"
"""The firmware's PlatformIO project in the source tree."""
HOST_SUFFIX = "-host"
"""The end of the firmware version a host-built unit reports."""


class FirmwareBuildError(RuntimeError):
    """The host build could not be made (no compiler, CMake, or the source tree)."""


def build_host_firmware(build_dir: Path, source_dir: Path = FIRMWARE_DIR / "host") -> Path:
    """Compile the firmware's host build into `build_dir`; return the folder holding
    `haptic_unit_host` and `haptic_unit_tests`.

    Raises
    ------
    FirmwareBuildError
        CMake or a C++ compiler is missing, or the build failed (its output attached).
    """
    if not (source_dir / "CMakeLists.txt").is_file():
        raise FirmwareBuildError(
            f"no firmware host build at {source_dir}; expected the source tree"
        )
    cmake = shutil.which("cmake")
    if cmake is None:
        raise FirmwareBuildError("cmake not found; expected CMake and a C++ compiler (g++)")
    steps = (
        [cmake, "-S", str(source_dir), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release"],
        [cmake, "--build", str(build_dir), "-j", "2"],
    )
    for step in steps:
        done = subprocess.run(step, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise FirmwareBuildError(
                f"{' '.join(step)} failed:\n{done.stdout[-2000:]}{done.stderr[-2000:]}"
            )
    return build_dir


class HostUnit:
    """One host-built unit (`role` "dial" or "drive") on a pty, as a context manager.

    `hand`, `joystick` and `button` are the simulated person's scripts on a dial
    ("t:value,..." in s and rad / axis units, linear between the points, restarted at
    each HELLO; the button is held where its script is 0.5 or more);
    `link`, given, is a symlink to the pty that stays the unit's port across restarts;
    `corrupt_every` > 0 garbles every so many state lines on the wire (their angle field
    overwritten, their checksum kept).
    """

    def __init__(
        self,
        build_dir: Path,
        role: str = "dial",
        hand: str = "0",
        joystick: str = "0",
        seed: int = 1,
        link: Path | None = None,
        corrupt_every: int = 0,
        button: str = "0",
    ) -> None:
        self.binary = Path(build_dir) / "haptic_unit_host"
        self.role, self.hand, self.joystick, self.seed, self.link = role, hand, joystick, seed, link
        self.corrupt_every = corrupt_every
        self.button = button
        self.process: subprocess.Popen[str] | None = None
        self.port = ""

    def start(self) -> HostUnit:
        command = [
            str(self.binary),
            "--role",
            self.role,
            "--hand",
            self.hand,
            "--joystick",
            self.joystick,
            "--seed",
            str(self.seed),
            "--button",
            self.button,
        ]
        if self.link is not None:
            command += ["--link", str(self.link)]
        if self.corrupt_every:
            command += ["--corrupt-every", str(self.corrupt_every)]
        if not self.binary.is_file():
            raise FirmwareBuildError(f"no {self.binary}; expected build_host_firmware's folder")
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
        stdout = self.process.stdout
        first = stdout.readline().split() if stdout is not None else []
        if len(first) != 2 or first[0] != "PORT":
            self.process.kill()
            self.process.wait()
            raise FirmwareBuildError(f"{self.binary} did not report its port (got {first!r})")
        self.port = str(self.link) if self.link is not None else first[1]
        return self

    def unplug(self) -> None:
        """Kill the unit: its pty goes away under whoever has it open."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()

    def freeze(self) -> None:
        """The unit stops answering (its process stopped), its port still there."""
        if self.process is not None:
            os.kill(self.process.pid, signal.SIGSTOP)

    def thaw(self) -> None:
        if self.process is not None:
            os.kill(self.process.pid, signal.SIGCONT)

    def press(self) -> None:
        """The participant presses the dial's button (held down 0.1 s), as when the tip
        has reached the target."""
        if self.process is not None:
            os.kill(self.process.pid, signal.SIGUSR1)

    def stop(self) -> None:
        if self.process is None or self.process.poll() is not None:
            return
        self.thaw()
        self.process.terminate()
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()

    def __enter__(self) -> HostUnit:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
        if self.process is not None and self.process.stdout is not None:
            self.process.stdout.close()
