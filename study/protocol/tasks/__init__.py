"""Tasks: what a trial is, in one place per task, and the registry that knows them.

A task (the LCCA guidewire navigation, the NOTES endoscopy, or one a lab adds) is a
`Task`: it builds the trial's closed loop and the simulated participant's driver, names
its regions, its sample columns (with units, and which column of the `samples` table
stores each), its summary measures (stored in `trial_measures` under their own names,
exported and analysed under them), and what the live view and the figures draw. The
session runner, `study simulate`, `study run`, the exports, the analysis and the TUI ask
the registry (`get_task`, `task_names`); nothing outside a task's module compares task
names.

The built-in tasks are listed in `BUILTIN`; `register(task)` adds one (a test, a lab's
own module), and installed packages may add theirs under the entry-point group
`haptic_study.tasks` (each entry point names a `Task` instance). "Adding a task" in the
README walks through it.

This module imports nothing heavy (the TUI and `study` read designs before numpy loads):
a task's module imports its loop and its numerics inside its methods.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from study.errors import StudyInputError
from study.protocol.tasks.declarations import (
    MAX_HAPTIC_GAIN_N_M_PER_N,
    LiveTrace,
    Measure,
    SampleColumn,
    pose_columns,
)

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    import pyarrow as pa

    from teleop_core.loop.drivers import Driver

BUILTIN = ("study.tasks.lcca.task", "study.tasks.notes.task")
"""The modules of the tasks that come with the tool, each registering its `TASK`."""
__all__ = [
    "COMPLETION_TIME",
    "LiveTrace",
    "Measure",
    "SampleColumn",
    "Task",
    "TrialResult",
    "get_task",
    "is_task",
    "measure_named",
    "pose_columns",
    "register",
    "task_names",
    "tasks",
    "unregister",
]
ENTRY_POINT_GROUP = "haptic_study.tasks"
COMPLETION_TIME = "completion_time_s"
"""Every task's first measure: seconds from the first sample to the trial's end."""


@dataclass
class TrialResult:
    """One headless simulated trial: its TRIAL.csv frame and its summary."""

    frame: pd.DataFrame
    """TRIAL.csv: the task's sample columns under its own names."""
    summary: dict[str, Any] = field(default_factory=dict)


class Traits(Protocol):
    """A simulated person (`study.tasks.lcca.simulated_participant.ParticipantTraits`; named here by
    what a task uses of it, so that the registry does not import the participants)."""

    @property
    def group(self) -> str: ...

    def to_dict(self) -> dict[str, Any]: ...


class TrialLoop(Protocol):
    """What the session runner needs of a task's closed loop."""

    t_s: float
    done: bool
    success: bool

    def start(self, driver: Driver) -> None: ...
    def advance(self, duration_s: float) -> np.ndarray: ...


class Task:
    """One task of a study. Subclass, set the class attributes, implement the methods."""

    name: ClassVar[str]
    """The design's and the database's name for it (`lcca`)."""
    title: ClassVar[str]
    """For people: `LCCA guidewire navigation`."""
    has_dial: ClassVar[bool] = False
    """The haptic dial renders force in HV at a gain (`haptic_gain_n_m_per_n`)."""
    default_haptic_gain_n_m_per_n: ClassVar[float | None] = None
    """The dial's haptic gain when the design sets none, N m/N (None: no dial)."""
    has_link: ClassVar[bool] = False
    """Master and follower talk over a link whose delay, jitter and loss can be set."""
    regions: ClassVar[tuple[str, ...]]
    """Where the tip can be; `samples.branch` stores the name, the loop the index."""
    sample_columns: ClassVar[tuple[SampleColumn, ...]]
    """The columns of the loop's sample rows, in order (`pose_columns` first)."""
    measures: ClassVar[tuple[Measure, ...]]
    """The trial's summary measures after `completion_time_s` (see `all_measures`)."""
    live_traces: ClassVar[tuple[LiveTrace, LiveTrace]]
    """The two forces the live view plots while a trial runs."""
    live_peaks: ClassVar[tuple[LiveTrace, LiveTrace]]
    """The two peaks reported when a trial ends (as stored measures)."""
    live_scene: ClassVar[str | None] = None
    """The widget the run screen draws beside the readout, as `module:Class` (a Textual
    widget of the task's package with `update_frame(frame)`, imported by the TUI when it
    shows the task); None: the insertion along a bar (`study.tui.scenes.TrackView`)."""
    live_scene_title: ClassVar[str] = "{title}: insertion"
    """The live view's title (`{title}`: the task's `title`)."""
    keyboard_aim_label: ClassVar[str] = "dial aim"
    """What the keyboard driver's aim sets, as the run screen names it (the dial's angle;
    a task whose dial sets a speed says so)."""
    key_hints: ClassVar[str] = "↑↓ dial ←→ rotate space let go e end"
    """The keyboard driver's keys, as the run screen lists them."""
    track_length_m: ClassVar[float] = 0.5
    """The `track` scene's full length of insertion, m."""
    trace_names: ClassVar[dict[str, str]]
    """Force columns (the task's sample column names) -> legend label, for the
    force-trace figure, in the order of `study.analysis.trace_figure.STYLES`."""
    sign_note: ClassVar[str] = ""
    """The sign convention of the traced forces, under the figure."""
    trace_measure: ClassVar[str] = ""
    """The measure whose highest VO trial Fig. 9 draws (default: the last analysed one)."""

    # -- the trial --------------------------------------------------------------------

    def session_context(self) -> Any:
        """What the trials of one session share, built once per session.

        Returns
        -------
        Any
            The shared state (e.g. a phantom), handed to `make_loop` and
            `simulated_driver`; None (the default) for a task that shares nothing.
        """
        return None

    def make_loop(
        self,
        condition: str,
        seed: int,
        *,
        haptic_gain_n_m_per_n: float | None = None,
        estimator: Any = None,
        context: Any = None,
        link: Any = None,
    ) -> TrialLoop:
        """The closed loop of one trial, not started.

        Parameters
        ----------
        condition : str
            ``"VO"`` or ``"HV"``.
        seed : int
            Seeds the trial's randomness (the same seed gives the same trial).
        haptic_gain_n_m_per_n : float or None, optional
            The dial's haptic gain, N m/N, where the task has a dial (None: the task's
            default).
        estimator : ForceEstimator or None, optional
            The follower's force estimator, for tasks that estimate the force.
        context : Any, optional
            What `session_context` built for the session.
        link : LinkParams or None, optional
            The master-follower link's delay, jitter and loss
            (`teleop_core.loop.link.LinkParams`) where the task has one.

        Returns
        -------
        TrialLoop
            The loop; the session runner starts it with a driver and advances it.
        """
        raise NotImplementedError

    def simulated_driver(self, traits: Traits, max_s: float, context: Any) -> Driver:
        """The simulated participant's hand for one trial.

        Parameters
        ----------
        traits : Traits
            The simulated person (`study.protocol.traits.ParticipantTraits`).
        max_s : float
            The trial's time limit, s (the person gives up by then).
        context : Any
            What `session_context` built for the session.

        Returns
        -------
        Driver
            The driver the loop asks for the hand's action each step.
        """
        raise NotImplementedError

    def trial_measures(
        self, samples: np.ndarray, success: bool
    ) -> tuple[dict[str, float], dict[str, Any]]:
        """The measures of one trial.

        Parameters
        ----------
        samples : numpy.ndarray
            The trial's samples: the loop's rows, in `sample_columns`' order.
        success : bool
            Whether the trial reached its goal.

        Returns
        -------
        tuple of (dict of str to float, dict of str to Any)
            The stored measures by name (the task's `measures`; `completion_time_s` is
            added by the caller) and further summary values.
        """
        raise NotImplementedError

    def trial_figure(self, frame: pd.DataFrame, title: str) -> Any:
        """The matplotlib figure `study simulate --plot` draws of one trial.

        Parameters
        ----------
        frame : pandas.DataFrame
            The trial's TRIAL.csv frame (the task's sample columns under its own names).
        title : str
            The figure's title.

        Returns
        -------
        matplotlib.figure.Figure or None
            The figure, drawn by the task's package; None (the default): the insertion
            and the live traces over time (`study.analysis.trial_plot.traces_plot`).
        """
        return None

    fit_features: ClassVar[tuple[str, ...]] = ()
    """`trial_features`' keys: a trial frame's features for the participant fit (> 0, SI)."""

    def trial_features(self, frame: pd.DataFrame, context: Any) -> dict[str, float]:
        """The participant fit's features of one trial.

        Parameters
        ----------
        frame : pandas.DataFrame
            The trial's samples under the task's column names (its TRIAL.csv frame).
        context : Any
            What `session_context` built.

        Returns
        -------
        dict of str to float
            `fit_features` -> value (NaN where the trial does not show it); empty for a
            task the participant fit does not cover.
        """
        return {}

    def completion_time_s(self, samples: np.ndarray) -> float:
        """The time of the trial's last sample.

        Parameters
        ----------
        samples : numpy.ndarray
            The trial's samples: the loop's rows, in `sample_columns`' order.

        Returns
        -------
        float
            The last sample's time, s; 0 without samples.
        """
        if not len(samples):
            return 0.0
        return float(samples[-1, self.column_index()[self.stored_name("t_s")]])

    def summary_line(self, summary: Mapping[str, Any]) -> str:
        """The measures of a simulated trial's summary, for one printed line.

        Parameters
        ----------
        summary : Mapping of str to Any
            A trial's summary (`TrialResult.summary`): measure name -> value.

        Returns
        -------
        str
            ``label value unit`` for each of the task's `measures` in the summary,
            separated by commas.
        """
        return ", ".join(
            f"{m.label} {summary[m.name]:.3g}{' ' + m.unit if m.unit else ''}"
            for m in self.measures
            if m.name in summary
        )

    def driver_counts(self, driver: Driver) -> dict[str, int]:
        """What a simulated participant noticed during the trial.

        Parameters
        ----------
        driver : teleop_core.loop.drivers.Driver
            The simulated participant's driver after the trial.

        Returns
        -------
        dict of str to int
            Counts kept in the trial's summary (name -> count); empty by default.
        """
        return {}

    def trial_frame(self, samples: np.ndarray) -> pd.DataFrame:
        """TRIAL.csv: the samples under the task's own column names, regions by name.

        Parameters
        ----------
        samples : numpy.ndarray
            The trial's samples: the loop's rows, in `sample_columns`' order.

        Returns
        -------
        pandas.DataFrame
            One column per sample column, named as the task names it; the region
            column holds the region's name (from `regions`), not its index.
        """
        import numpy as np
        import pandas as pd

        frame = pd.DataFrame(samples, columns=[c.name for c in self.sample_columns])
        region = self.region_column
        codes = frame[region].to_numpy().astype(int)
        frame[region] = np.asarray(self.regions, dtype=object)[codes]
        return frame

    def live_lines(self, values: Mapping[str, float], condition: str | None = None) -> list[str]:
        """Readout lines under the live gauges, from the newest sample.

        Parameters
        ----------
        values : Mapping of str to float
            The newest sample by the task's column names (insertion in m, rotation in
            rad, the region as its index in `regions`).
        condition : str or None, optional
            The trial's condition (``"VO"`` or ``"HV"``); None: not known.

        Returns
        -------
        list of str
            The lines to show (by default the region, the insertion in mm and the
            rotation in rad).
        """
        region = self.regions[int(values[self.region_column])]
        return [
            f"in {region}, inserted {values[self.stored_name('insertion_m')] * 1000:5.0f} mm",
            f"rotation {values[self.stored_name('rotation_rad')]:+5.2f} rad",
        ]

    @property
    def all_measures(self) -> tuple[Measure, ...]:
        """Every stored measure: `completion_time_s` first, then the task's `measures`.

        Returns
        -------
        tuple of Measure
            The measures in the order they are stored and exported.
        """
        return (
            Measure(COMPLETION_TIME, "s", "completion time", "seconds to the trial's end"),
            *self.measures,
        )

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if not cls.__dict__.get("trace_measure") and "measures" in cls.__dict__:
            analysed = [m.name for m in cls.measures if m.analysed]
            cls.trace_measure = analysed[-1] if analysed else COMPLETION_TIME

    @property
    def analysed_measures(self) -> tuple[str, ...]:
        """The names of the measures the statistics and figures analyse.

        Returns
        -------
        tuple of str
            The names of `all_measures` whose `Measure.analysed` is true, in order.
        """
        return tuple(m.name for m in self.all_measures if m.analysed)

    def stored_name(self, stored_as: str) -> str:
        """The task's name of the sample column stored as `stored_as`.

        Parameters
        ----------
        stored_as : str
            A role in the loop's layout (`SampleColumn.stored_as`), e.g. ``"t_s"``.

        Returns
        -------
        str
            The `SampleColumn.name` of the task's column with that role.

        Raises
        ------
        StopIteration
            No sample column of the task has that role.
        """
        return next(c.name for c in self.sample_columns if c.stored_as == stored_as)

    @property
    def region_column(self) -> str:
        """The sample column `samples.branch` stores: the region's index in `regions`."""
        return self.stored_name("branch")

    def column_index(self) -> dict[str, int]:
        """Where each sample column sits in the loop's rows.

        Returns
        -------
        dict of str to int
            `SampleColumn.name` -> its index in `sample_columns` (and in a row).
        """
        return {c.name: k for k, c in enumerate(self.sample_columns)}

    def sample_schema(self) -> pa.Schema:
        """The Arrow schema the task's samples are stored in.

        Returns
        -------
        pyarrow.Schema
            The task's sample columns in order under its own names, each with its unit
            and description in the field's metadata; the region column is text.
        """
        import pyarrow as pa

        from db.sample_codec import sample_field

        region = self.region_column
        return pa.schema(
            [
                sample_field(c.name, c.unit, c.description, text=c.name == region)
                for c in self.sample_columns
            ]
        )

    def stored_columns(self, samples: np.ndarray) -> dict[str, Any]:
        """A batch of loop rows as the stored columns, by the task's names.

        Parameters
        ----------
        samples : numpy.ndarray
            Loop rows, in `sample_columns`' order.

        Returns
        -------
        dict of str to Any
            `SampleColumn.name` -> that column's values (a numpy array; for the region
            column, a list of region names).
        """
        out: dict[str, Any] = {}
        region = self.region_column
        for k, column in enumerate(self.sample_columns):
            values = samples[:, k]
            if column.name == region:
                out[column.name] = [self.regions[int(v)] for v in values.tolist()]
            else:
                out[column.name] = values
        return out

    def stored_table(self, table: pa.Table) -> pa.Table:
        """Samples read from the database under the task's own columns.

        Chunks stored in the layout of before the tasks' own schemas
        (`SampleColumn.stored_as`) are renamed; a column they lack is NULL.

        Parameters
        ----------
        table : pyarrow.Table
            Samples as `db.sample_reader` reads them, in either layout.

        Returns
        -------
        pyarrow.Table
            The key columns (`trial_id`, `seq`) kept in front, then every sample column
            in the task's order, typed as in `sample_schema`.
        """
        import pyarrow as pa

        keys = [k for k in ("trial_id", "seq") if k in table.column_names]
        values = [n for n in table.column_names if n not in keys]
        own = values == [c.name for c in self.sample_columns]
        arrays = [table[k] for k in keys]
        fields = [table.schema.field(k) for k in keys]
        for column, own_field in zip(self.sample_columns, self.sample_schema(), strict=True):
            source = column.name if own else column.stored_as
            if source is not None and source in values:
                arrays.append(table[source].cast(own_field.type))
            else:
                arrays.append(pa.nulls(table.num_rows, own_field.type))
            fields.append(own_field)
        return pa.Table.from_arrays(arrays, schema=pa.schema(fields))

    def haptic_gain(self, gain_n_m_per_n: float | None) -> float | None:
        """The haptic gain a trial runs at.

        Parameters
        ----------
        gain_n_m_per_n : float or None
            The asked-for gain of the haptic dial, N m/N; None: the task's default.

        Returns
        -------
        float or None
            `gain_n_m_per_n`, else `default_haptic_gain_n_m_per_n`.

        Raises
        ------
        StudyInputError
            A gain is given for a task without a dial, or it is not finite or lies
            outside 0 to `MAX_HAPTIC_GAIN_N_M_PER_N` (the bound a design file has).
        """
        if gain_n_m_per_n is None:
            return self.default_haptic_gain_n_m_per_n
        if not self.has_dial:
            raise StudyInputError(
                f"haptic gain {gain_n_m_per_n!r} for the {self.name} task, which has no "
                "haptic dial; expected no gain for it"
            )
        if not (math.isfinite(gain_n_m_per_n) and 0 <= gain_n_m_per_n <= MAX_HAPTIC_GAIN_N_M_PER_N):
            raise StudyInputError(
                f"haptic gain {gain_n_m_per_n!r}; expected 0 to {MAX_HAPTIC_GAIN_N_M_PER_N:g} N m/N"
            )
        return gain_n_m_per_n


_REGISTRY: dict[str, Task] = {}
_LOADED = _ENTRY_POINTS_LOADED = False


def register(task: Task) -> Task:
    """Add `task` to the registry, replacing one of the same name.

    Parameters
    ----------
    task : Task
        A `Task` instance.

    Returns
    -------
    Task
        `task` itself (so a module can write ``TASK = register(MyTask())``).

    Raises
    ------
    ValueError
        Its name is not an identifier of at most 16 characters, or it stores no sample
        column as one of ``t_s``, ``branch``, ``insertion_m``, ``rotation_rad``.
    """
    if not getattr(task, "name", "") or not task.name.isidentifier() or len(task.name) > 16:
        raise ValueError(
            f"task name {getattr(task, 'name', None)!r}; expected an identifier "
            "of at most 16 characters"
        )
    stored = [c.stored_as for c in task.sample_columns]
    for required in ("t_s", "branch", "insertion_m", "rotation_rad"):
        if required not in stored:
            raise ValueError(f"task {task.name}: no sample column stored as {required!r}")
    _REGISTRY[task.name] = task
    return task


def unregister(name: str) -> None:
    """Remove the task called `name` from the registry (nothing if there is none)."""
    _REGISTRY.pop(name, None)


def _load(entry_points_too: bool = False) -> None:
    """The built-in tasks on first use; the installed packages' (entry points: a scan of
    every distribution's metadata) only when a name is not built in or all are asked for."""
    global _LOADED, _ENTRY_POINTS_LOADED
    if not _LOADED:
        _LOADED = True
        for module in BUILTIN:
            importlib.import_module(module)
    if entry_points_too and not _ENTRY_POINTS_LOADED:
        _ENTRY_POINTS_LOADED = True
        from importlib.metadata import entry_points

        for entry in entry_points(group=ENTRY_POINT_GROUP):
            register(entry.load())


def is_task(name: str) -> bool:
    """Whether a task called `name` is built in, registered or installed."""
    _load()
    if name not in _REGISTRY:
        _load(entry_points_too=True)
    return name in _REGISTRY


def task_names() -> tuple[str, ...]:
    """The tasks a design may name.

    Returns
    -------
    tuple of str
        The built-in tasks' names first, then those registered or installed (entry
        point group ``haptic_study.tasks``).
    """
    _load(entry_points_too=True)
    return tuple(_REGISTRY)


def get_task(name: str) -> Task:
    """The task called `name`.

    Parameters
    ----------
    name : str
        A task's name, e.g. ``"lcca"``.

    Returns
    -------
    Task
        The registered task.

    Raises
    ------
    StudyInputError
        No task has that name; the one-line message lists the known ones.
    """
    if not is_task(name):
        raise StudyInputError(not_installed(name))
    return _REGISTRY[name]


INSTALL_HINTS = {"probe": "study example-data DIR && pip install DIR/probe_task"}
"""How to install the tasks whose packages ship with haptic-study as examples."""


def not_installed(name: str) -> str:
    """The one line for a task name no built-in task or installed package has: the task
    is named as not installed, with how to install it where that is known."""
    how = INSTALL_HINTS.get(
        name, f"pip install the package whose {ENTRY_POINT_GROUP} entry point is {name!r}"
    )
    return f"task {name!r} is not installed: {how}; installed: {', '.join(task_names())}"


def measure_named(name: str) -> Measure | None:
    """The measure called `name` in the first registered task that has it."""
    for task in tasks():
        for m in task.all_measures:
            if m.name == name:
                return m
    return None


def tasks() -> tuple[Task, ...]:
    """Every known task, in `task_names`' order."""
    _load(entry_points_too=True)
    return tuple(_REGISTRY.values())
