"""The `Task` a task implements: one frozen declaration (`TaskDeclaration`: its regions,
sample columns and measures) and three hooks, an ABC so that a task that forgets one is
refused when it is made, not in the middle of a trial.

The rest of `Task` is derived from the declaration (the stored schema, TRIAL.csv, the
measures' order) and may be left as it is. The trial loop is not here: it is
`study.protocol.trial_run.run_trial`, the same for every task. This module imports
nothing heavy (the TUI and `study` read designs before numpy loads).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from study.errors import StudyInputError
from study.protocol.tasks.declarations import MAX_HAPTIC_GAIN_N_M_PER_N, Measure, SampleColumn

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    import pyarrow as pa

    from teleop_core.loop.drivers import Driver

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


@dataclass(frozen=True)
class TaskDeclaration:
    """What a task is, declared once: its name, regions, sample columns and measures.

    The loop's rows, the stored samples, TRIAL.csv, the export and the figures all
    take the sample columns from here; the trial's measures are stored under `measures`'
    names."""

    name: str
    """The design's and the database's name for it (`lcca`): an identifier of at most
    16 characters."""
    title: str
    """For people: `LCCA guidewire navigation`."""
    regions: tuple[str, ...]
    """Where the tip can be; the stored samples hold the name, the loop the index."""
    sample_columns: tuple[SampleColumn, ...]
    """The columns of the loop's sample rows, in order (`pose_columns` first)."""
    measures: tuple[Measure, ...]
    """The trial's summary measures after `completion_time_s` (see `Task.all_measures`)."""
    region_column: str
    """The sample column of the region: the loop's index in `regions`, stored as the
    region's name."""
    has_dial: bool = False
    """The haptic dial renders force in HV at a gain (`haptic_gain_n_m_per_n`)."""
    default_haptic_gain_n_m_per_n: float | None = None
    """The dial's haptic gain when the design sets none, N m/N (None: no dial)."""
    has_link: bool = False
    """Master and follower talk over a link whose delay, jitter and loss can be set."""
    fit_features: tuple[str, ...] = ()
    """`Task.trial_features`' keys: a trial frame's features for the participant fit."""


class Task(ABC):
    """One task of a study: its `declaration` and three hooks (`make_loop`,
    `simulated_driver`, `trial_measures`); `study.protocol.trial_run.run_trial` runs its
    trials. What the terminal app and the figures draw of it are views of their own
    (`study.tui.task_views`, `study.analysis.task_figures`)."""

    declaration: ClassVar[TaskDeclaration]

    @property
    def name(self) -> str:
        return self.declaration.name

    @property
    def title(self) -> str:
        return self.declaration.title

    @property
    def regions(self) -> tuple[str, ...]:
        return self.declaration.regions

    @property
    def sample_columns(self) -> tuple[SampleColumn, ...]:
        return self.declaration.sample_columns

    @property
    def measures(self) -> tuple[Measure, ...]:
        return self.declaration.measures

    @property
    def has_dial(self) -> bool:
        return self.declaration.has_dial

    @property
    def default_haptic_gain_n_m_per_n(self) -> float | None:
        return self.declaration.default_haptic_gain_n_m_per_n

    @property
    def has_link(self) -> bool:
        return self.declaration.has_link

    @property
    def fit_features(self) -> tuple[str, ...]:
        return self.declaration.fit_features

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

    @abstractmethod
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
            The loop; `run_trial` starts it with a driver and advances it.
        """

    @abstractmethod
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

    @abstractmethod
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
            added by `run_trial`) and further summary values.
        """

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
        return float(samples[-1, 0])  # `t_s`, the first column (`pose_columns`)

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

    @property
    def analysed_measures(self) -> tuple[str, ...]:
        """The names of the measures the statistics and figures analyse.

        Returns
        -------
        tuple of str
            The names of `all_measures` whose `Measure.analysed` is true, in order.
        """
        return tuple(m.name for m in self.all_measures if m.analysed)

    @property
    def region_column(self) -> str:
        """The sample column of the region (the loop's index in `regions`)."""
        return self.declaration.region_column

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

    def sample_table(self, table: pa.Table) -> pa.Table:
        """Samples read from the database, in the task's columns and types.

        Parameters
        ----------
        table : pyarrow.Table
            Samples as `db.sample_reader` reads them: the key columns and the columns
            of the chunks' schema (the task's, perhaps of an older version of it).

        Returns
        -------
        pyarrow.Table
            The key columns (`trial_id`, `seq`) kept in front, then every sample column
            in the task's order, typed as in `sample_schema`, by name; a column the
            chunks lack is NULL.
        """
        import pyarrow as pa

        keys = [k for k in ("trial_id", "seq") if k in table.column_names]
        arrays = [table[k] for k in keys]
        fields = [table.schema.field(k) for k in keys]
        for own_field in self.sample_schema():
            if own_field.name in table.column_names:
                arrays.append(table[own_field.name].cast(own_field.type))
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
