"""haptic-study: plan, run, store and analyse user studies of haptic teleoperation.

`study.protocol` (designs, schedules, sessions, NASA-TLX), `study.analysis`
(statistics, figures), `study.tui` (the terminal app) and `study.cli` (the `study`
command) build on `db` and `teleop_core`, never the other way round.
"""
