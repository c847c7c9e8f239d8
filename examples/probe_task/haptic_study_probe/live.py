"""The probe task on haptic-study's run screen: the push and the aim on the gauges, the
insertion along a 100 mm bar. The entry point `haptic_study.live_views: probe` names
`VIEW`; the terminal app loads it when it draws the task (and only then)."""

from __future__ import annotations

from study.protocol.tasks import LiveTrace
from study.tui.task_views import LiveView

VIEW = LiveView(
    traces=(LiveTrace("push_force_n", "push", 2.0), LiveTrace("aim_rad", "aim", 1.0)),
    track_length_m=0.1,
)
