"""What the terminal app draws of a task while its trial runs: a `LiveView` per task,
kept here on the app's side so that a task (`study.protocol.tasks.Task`) declares its
data and hooks only and never imports the terminal app.

The built-in tasks' views are in `BUILTIN` (their scenes beside them); `register_view`
adds one, and installed packages may add theirs under the entry-point group
`haptic_study.live_views` (each entry point names a `LiveView`, under the task's name).
A task without a view gets `default_view(task)`: its first two sample columns after the
pose and the region, and the insertion along a bar.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from study.protocol.tasks import LiveTrace, Task
from study.protocol.tasks.views import ViewRegistry, default_traces

if TYPE_CHECKING:
    from textual.widget import Widget

BUILTIN = ("study.tui.scene_lcca", "study.tui.scene_notes")
"""The modules of the built-in tasks' views, each registering its `VIEW`."""
ENTRY_POINT_GROUP = "haptic_study.live_views"


def pose_lines(task: Task, values: Mapping[str, float], condition: str | None) -> list[str]:
    """The readout lines of a task without its own: region, insertion (mm), rotation.

    Parameters
    ----------
    task : Task
        The trial's task.
    values : Mapping of str to float
        The newest sample by the task's column names (the region as its index).
    condition : str or None
        The trial's condition (``"VO"`` or ``"HV"``); None: not known.

    Returns
    -------
    list of str
        The lines to show under the gauges.
    """
    columns = task.sample_columns
    region = task.regions[int(values[task.region_column])]
    return [
        f"in {region}, inserted {values[columns[1].name] * 1000:5.0f} mm",
        f"rotation {values[columns[2].name]:+5.2f} rad",
    ]


@dataclass(frozen=True)
class LiveView:
    """A task as the run screen draws it."""

    traces: tuple[LiveTrace, LiveTrace]
    """The two forces the live view plots while a trial runs."""
    peaks: tuple[LiveTrace, LiveTrace] | None = None
    """The two peaks reported when a trial ends (as stored measures); None: `traces`."""
    scene: type[Widget] | None = None
    """The widget drawn beside the readout (with `update_frame(frame)`); None: the
    insertion along a bar (`study.tui.scenes.TrackView`)."""
    scene_title: str = "{title}: insertion"
    """The live view's title (`{title}`: the task's `title`)."""
    keyboard_aim_label: str = "dial aim"
    """What the keyboard driver's aim sets, as the run screen names it."""
    key_hints: str = "↑↓ dial ←→ rotate space let go e end"
    """The keyboard driver's keys, as the run screen lists them."""
    track_length_m: float = 0.5
    """The bar's full length of insertion, m (for a view without its own scene)."""
    lines: Callable[[Task, Mapping[str, float], str | None], list[str]] = pose_lines
    """Readout lines under the gauges from the newest sample (`pose_lines`' arguments)."""

    @property
    def shown_peaks(self) -> tuple[LiveTrace, LiveTrace]:
        """`peaks`, else `traces`."""
        return self.peaks if self.peaks is not None else self.traces


_VIEWS: ViewRegistry[LiveView] = ViewRegistry(BUILTIN, ENTRY_POINT_GROUP)


def register_view(name: str, view: LiveView) -> LiveView:
    """Draw the task called `name` with `view` (replacing one it had); `view` returned."""
    return _VIEWS.register(name, view)


def default_view(task: Task) -> LiveView:
    """The view of a task nobody registered one for: its first two sample columns after
    the pose and the region, each on a gauge of full scale 1 in its unit."""
    return LiveView(default_traces(task))


def live_view(task: Task) -> LiveView:
    """The view `task` is drawn with: its registered one, else `default_view`."""
    view = _VIEWS.get(task.name)
    return view if view is not None else default_view(task)
