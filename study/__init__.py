"""haptic-study: plan, run, store and analyse user studies of haptic teleoperation.

`study.protocol` (designs, schedules, sessions, NASA-TLX), `study.analysis`
(statistics, figures), `study.tui` (the terminal app) and `study.cli` (the `study`
command) build on `db` and `teleop_core`, never the other way round.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("haptic-study")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"
