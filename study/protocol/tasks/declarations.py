"""What a task declares about its data: its summary measures (`Measure`), the columns of
its sample rows (`SampleColumn`, `pose_columns`) and the forces its live view traces
(`LiveTrace`). Plain frozen records, importable without the registry or numpy; the
registry (`study.protocol.tasks`) re-exports them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

MAX_HAPTIC_GAIN_N_M_PER_N = 1.0
"""Far above any usable gain (the paper's is 0.02 N m/N; the dial saturates at 0.1 N m)."""


@dataclass(frozen=True)
class Measure:
    """One summary measure of a trial: stored, exported and analysed by `name`."""

    name: str
    """With its unit in the name (`peak_tip_force_n`)."""
    unit: str
    """SI unit as printed (``"N"``, ``"s"``), empty for a count."""
    label: str
    """Axis label, without the unit (`peak tip force`)."""
    description: str
    """What it is (the codebook's text)."""
    analysed: bool = True
    """In the statistics and figures (else stored and exported only)."""
    max_value: float | None = None
    """Largest value an import accepts (a device's bound); None: no bound."""
    integer: bool = False
    """A count: its values are whole numbers (e.g. wall contacts)."""

    @property
    def axis_label(self) -> str:
        """The axis label with the unit in brackets, e.g. ``peak tip force (N)``."""
        return f"{self.label} ({self.unit})" if self.unit else self.label


@dataclass(frozen=True)
class SampleColumn:
    """One column of the task's sample rows, in the loop's order; stored, exported and
    drawn under `name` (the task's chunks' schema is its columns, `Task.sample_schema`)."""

    name: str
    """The one name of the quantity, from the loop's rows to TRIAL.csv, the stored
    samples, the export and the figures."""
    unit: str
    description: str


def pose_columns(
    insertion: str,
    rotation: str,
    tip: str,
    *,
    insertion_name: str = "insertion_m",
    rotation_name: str = "rotation_rad",
) -> tuple[SampleColumn, ...]:
    """The first six columns every task's rows start with, in this order: time,
    insertion depth, roll and the tip's position, each described in the task's words
    (the live view and the figures find them by their place)."""
    return (
        SampleColumn("t_s", "s", "time since the trial started"),
        SampleColumn(insertion_name, "m", insertion),
        SampleColumn(rotation_name, "rad", rotation),
        *(SampleColumn(f"tip_{axis}_m", "m", tip) for axis in "xyz"),
    )


def described(
    names: Sequence[str], meanings: Mapping[str, tuple[str, str]]
) -> tuple[SampleColumn, ...]:
    """A task's sample columns from its loop's layout: the column names in the order the
    loop writes them (the loop's one declaration of them, e.g.
    `teleop_core.loop.layout.SAMPLE_COLUMNS`), each with the unit and meaning the task
    gives it in `meanings` (name -> (unit, description)).

    Raises
    ------
    ValueError
        A column of the layout has no meaning, or a meaning names no column of it (a
        layout and a task that disagree fail where the task is declared, not in a trial).
    """
    missing = [n for n in names if n not in meanings]
    extra = [n for n in meanings if n not in names]
    if missing or extra:
        raise ValueError(
            f"sample columns: the layout's {missing} have no meaning, "
            f"the meanings of {extra} name no column of the layout"
        )
    return tuple(SampleColumn(n, *meanings[n]) for n in names)


@dataclass(frozen=True)
class LiveTrace:
    """A force the live view plots (and whose peak it shows when the trial ends)."""

    column: str
    """A `SampleColumn.name`."""
    label: str
    full_scale: float
    """The gauge's full scale, in the column's unit."""
    magnitude: bool = False
    """Plot |value| (pushes and pulls alike)."""
