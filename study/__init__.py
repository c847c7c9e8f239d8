"""haptic-study: plan, run, store and analyse user studies of haptic teleoperation.

`study.protocol` (designs, schedules, sessions, NASA-TLX), `study.analysis`
(statistics, figures), `study.tui` (the terminal app) and `study.cli` (the `study`
command) build on `db` and `teleop_core`, never the other way round.
"""


def __getattr__(name: str) -> str:
    """`study.__version__`, read from the installed metadata on first use (importing
    `importlib.metadata` at start costs `study tui` some 30 ms)."""
    if name != "__version__":
        raise AttributeError(f"module 'study' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("haptic-study")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "0+unknown"
