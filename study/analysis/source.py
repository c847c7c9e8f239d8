"""Where the analysed data came from: who drove each trial (simulated or measured).

Simulated data never pass for measured data: every table, JSON, methods text and figure
drawn from the database carries a `DataSource`, the count of analysed trials by driver
(`trials.driver`: simulated, keyboard, hardware, imported), and, when any of them is
simulated, a note that says so ("simulated participants", or the mix).

`restrict` keeps one kind of driver (`--driver`). A questionnaire has no driver of its
own: it belongs to the block (participant, task, condition) it was filled in after, so
it is kept with that block's trials.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from study.errors import StudyInputError

if TYPE_CHECKING:  # the CLI imports DRIVERS for its options without loading pandas
    import pandas as pd

DRIVERS = ("simulated", "keyboard", "hardware", "imported")
"""The values of `trials.driver` (db.models.trial)."""
UNKNOWN = "unknown"
"""Trials stored without a driver (none are written so; kept visible if one is)."""


@dataclass(frozen=True)
class DataSource:
    """Analysed trials counted by driver."""

    trials_by_driver: dict[str, int]
    """Every driver of `DRIVERS` (0 when absent), plus `unknown` if a trial has none."""

    @classmethod
    def of(cls, trials: pd.DataFrame) -> DataSource:
        return cls.of_drivers(trials["driver"].tolist() if "driver" in trials else [])

    @classmethod
    def of_drivers(cls, drivers: list[Any]) -> DataSource:
        """The counts of the analysed trials' drivers (None or NaN: `UNKNOWN`)."""
        drivers = [d if isinstance(d, str) else UNKNOWN for d in drivers]
        counts = {d: drivers.count(d) for d in DRIVERS}
        if UNKNOWN in drivers:
            counts[UNKNOWN] = drivers.count(UNKNOWN)
        return cls(counts)

    @property
    def total(self) -> int:
        return sum(self.trials_by_driver.values())

    @property
    def simulated(self) -> int:
        return self.trials_by_driver["simulated"]

    @property
    def note(self) -> str:
        """'' when no trial is simulated; otherwise a line that says what is."""
        if not self.simulated:
            return ""
        if self.simulated == self.total:
            return f"Simulated participants: all {self.total} trials simulated, none measured"
        others = ", ".join(
            f"{n} {d}" for d, n in self.trials_by_driver.items() if n and d != "simulated"
        )
        return f"Mixed data: {self.simulated} of {self.total} trials simulated ({others})"

    @property
    def label(self) -> str:
        """One word for a CSV column: simulated, mixed, or the one measured driver."""
        kinds = [d for d, n in self.trials_by_driver.items() if n]
        if not kinds:
            return "none"
        return kinds[0] if len(kinds) == 1 else "mixed"

    def to_dict(self) -> dict[str, Any]:
        return {
            "trials_by_driver": dict(self.trials_by_driver),
            "label": self.label,
            "note": self.note,
        }


def restrict(
    trials: pd.DataFrame, tlx: pd.DataFrame, driver: str | None
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Only the trials of `driver` and the questionnaires of their blocks (None: all)."""
    if driver is None:
        return trials, tlx
    if driver not in DRIVERS:
        raise StudyInputError(f"driver {driver!r}; expected one of {', '.join(DRIVERS)}")
    kept = trials[trials["driver"] == driver]
    if not len(kept):
        present = DataSource.of(trials).trials_by_driver
        have = ", ".join(f"{d} ({n})" for d, n in present.items() if n) or "none stored"
        raise StudyInputError(f"no trials driven by {driver!r}; the database holds {have}")
    keys = ["participant", "task", "condition"]
    blocks = kept[keys].drop_duplicates()
    return kept, tlx.merge(blocks, on=keys, how="inner")[tlx.columns]
