"""Campaign files: the TOML a researcher writes, validated into a `CampaignSpec`, and its grid.

A campaign is the full grid of the `[factors]` values; each cell is simulated
`replicates` times, and each (cell, replicate) is one *unit*: a whole simulated study.
Every problem with the file is one line naming the key, the value and what was
expected (`StudyInputError`), raised before anything is run or written.

Seeds (common random numbers): a unit's study seed depends on the campaign's `seed`
and the replicate only, not on the cell, so replicate r of every cell has the same
simulated people (drawn as `study run` draws them from the study seed and their codes)
and the cells differ by their factors alone. It is also what makes the results the
same whatever order, or on whichever worker, the units run.

`participants = "MODEL.json"` (a path relative to the campaign file) draws the simulated
people from a fitted participant model (`study participants fit`) instead of the
hand-set profiles; the spec carries the model's text, so workers need no file, and a
campaign folder keeps a copy (`CampaignDir`).
"""

from __future__ import annotations

import itertools
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from study.errors import StudyInputError
from study.protocol.design import DEFAULT_GROUPS
from study.protocol.participant_model import ParticipantModel, load_model, model_from_dict
from study.protocol.tasks import get_task, is_task, task_names

FACTORS = ("haptic_gain", "link_delay_ms", "link_jitter_ms", "link_loss", "group_scale")
"""Factor names in the order of the results' columns."""
DEFAULTS = {
    "haptic_gain": 0.02,
    "link_delay_ms": 0.0,
    "link_jitter_ms": 0.0,
    "link_loss": 0.0,
    "group_scale": 1.0,
}
"""A factor not in `[factors]` takes this value: the device's G_h (N m per N, eq. 7), the
paper's wired link (IV-A), the design's group sizes."""
MIN_GROUP = 3
"""The fewest pairs the analysis tests (`compare_conditions` skips smaller groups)."""

TEMPLATE = """\
# A simulation campaign: `study campaign run THIS_FILE --out DIR`.
# Every unit (one cell of the [factors] grid x one replicate) simulates the whole study
# with simulated participants at the physics level, as `study run` does, and applies
# the analysis's VO-vs-HV test to each group and measure. Results are SIMULATED.

name = "LCCA power curve"
seed = 1                       # the same seed gives the same results, on any workers
replicates = 50                # simulated studies per cell
task = "lcca"                  # "lcca" (guidewire into the LCCA) or "notes" (endoscopy)
trials_per_condition = 1       # measured trials per participant in each condition
# participants = "model.json"  # people from a fitted model (`study participants fit`)

[groups]                       # group sizes, as in a design file (outsider, novice, expert)
outsider = 20
novice = 8
expert = 8

[factors]                      # lists of values; the campaign is their full grid
group_scale = [0.5, 1.0, 1.5]  # multiplies the group sizes (each must stay >= 3)
# haptic_gain = [0.0, 0.01, 0.02]     # G_h in N m per N (eq. 7); default 0.02 (LCCA only)
# link_delay_ms = [0, 50, 100]        # one-way delay, both directions (LCCA only)
# link_jitter_ms = [0, 10]            # extra delay, uniform in [0, value] (LCCA only)
# link_loss = [0.0, 0.05]             # probability a packet is lost, < 1 (LCCA only)
"""

_KEYS: dict[str, type | tuple[type, ...]] = {
    "name": str,
    "seed": int,
    "replicates": int,
    "task": str,
    "trials_per_condition": int,
    "groups": dict,
    "factors": dict,
    "participants": str,
}


@dataclass(frozen=True)
class Cell:
    """One point of the factor grid."""

    index: int
    """Position in the grid (factors varied in `FACTORS` order, the last fastest)."""
    values: dict[str, float]
    """The value of every factor, named or defaulted."""


@dataclass(frozen=True)
class CampaignSpec:
    name: str
    """What the campaign is for; written into the outputs."""
    seed: int
    """>= 0; with the replicate, seeds each unit's simulated study."""
    replicates: int
    """Simulated studies per cell; >= 1."""
    task: str
    """`lcca` or `notes`."""
    trials_per_condition: int
    """Measured trials per participant and condition; >= 1."""
    groups: dict[str, int]
    """Design group sizes, before `group_scale`."""
    factors: dict[str, tuple[float, ...]] = field(default_factory=dict)
    """The named factors' values, in `FACTORS` order."""
    participants_json: str = ""
    """The fitted participant model's file text ('' for the hand-set profiles)."""
    participants_digest: str = ""

    def participant_model(self) -> ParticipantModel | None:
        """The fitted model the people are drawn from, or None (the hand-set profiles)."""
        if not self.participants_json:
            return None
        data = json.loads(self.participants_json)
        return model_from_dict(data, f"campaign {self.name!r}", self.participants_digest)

    def cells(self) -> list[Cell]:
        names = list(self.factors)
        grid = itertools.product(*(self.factors[n] for n in names))
        return [
            Cell(k, {**DEFAULTS, **dict(zip(names, values, strict=True))})
            for k, values in enumerate(grid)
        ]

    def units(self) -> list[tuple[Cell, int]]:
        """Every (cell, replicate), cells outer."""
        return [(c, r) for c in self.cells() for r in range(self.replicates)]

    def sizes(self, cell: Cell) -> dict[str, int]:
        """The groups' sizes in `cell` (design sizes times `group_scale`, rounded)."""
        scale = cell.values["group_scale"]
        return {g: round(n * scale) for g, n in self.groups.items()}

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "seed": self.seed,
            "replicates": self.replicates,
            "task": self.task,
            "trials_per_condition": self.trials_per_condition,
            "groups": dict(self.groups),
            "factors": {k: list(v) for k, v in self.factors.items()},
            "participants": self.participants_digest or None,
        }


def unit_id(cell: Cell, replicate: int) -> str:
    """The file name stem of a unit's results, e.g. c0003-r0012."""
    return f"c{cell.index:04d}-r{replicate:04d}"


def study_seed(campaign_seed: int, replicate: int) -> int:
    """The simulated study's seed for `replicate` (the same in every cell)."""
    return int(np.random.SeedSequence([campaign_seed, replicate]).generate_state(1)[0])


def parse_campaign(text: str, source: str = "campaign") -> CampaignSpec:
    """Parse and validate a campaign file's text."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyInputError(f"{source} is not valid TOML: {exc}") from None
    return validate(data, source)


def _whole(source: str, key: str, value: Any, low: int) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < low:
        raise StudyInputError(f"{source}: {key} = {value!r}; expected a whole number >= {low}")
    return value


def _factor(source: str, name: str, values: Any) -> tuple[float, ...]:
    if not isinstance(values, list) or not values:
        raise StudyInputError(
            f"{source}: factors.{name} = {values!r}; expected a non-empty list of numbers"
        )
    for v in values:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise StudyInputError(f"{source}: factors.{name} value {v!r}; expected a finite number")
    out = tuple(float(v) for v in values)
    if len(set(out)) != len(out):
        raise StudyInputError(f"{source}: factors.{name} = {values!r}; expected each value once")
    bad = {
        "haptic_gain": (lambda v: v < 0, ">= 0 N m per N"),
        "link_delay_ms": (lambda v: v < 0, ">= 0 ms"),
        "link_jitter_ms": (lambda v: v < 0, ">= 0 ms"),
        "link_loss": (lambda v: not 0 <= v < 1, "a probability in [0, 1)"),
        "group_scale": (lambda v: v <= 0, "> 0"),
    }[name]
    for v in out:
        if bad[0](v):
            raise StudyInputError(f"{source}: factors.{name} value {v:g}; expected {bad[1]}")
    return out


def _participants(path: str | None, source: str, task: str) -> dict[str, str]:
    """The spec's fields for `participants = PATH` (relative to the campaign file)."""
    if path is None:
        return {}
    full = Path(source).parent / path
    model = load_model(full, task)  # one line if it is bad or fitted to another task
    return {"participants_json": full.read_text(), "participants_digest": model.digest}


def validate(data: dict[str, Any], source: str = "campaign") -> CampaignSpec:
    """A `CampaignSpec` from parsed TOML, or one `StudyInputError` line."""
    unknown = sorted(set(data) - set(_KEYS))
    if unknown:
        raise StudyInputError(
            f"{source}: unknown key {unknown[0]!r}; expected one of {', '.join(sorted(_KEYS))}"
        )
    missing = [k for k in ("seed", "replicates", "groups") if k not in data]
    if missing:
        raise StudyInputError(f"{source}: no {missing[0]!r}; expected e.g. {missing[0]} = ...")
    for key, kind in _KEYS.items():
        if key in data and not isinstance(data[key], kind):
            raise StudyInputError(
                f"{source}: {key} = {data[key]!r}; expected {getattr(kind, '__name__', kind)}"
            )
    task = data.get("task", "lcca")
    if not is_task(task):
        raise StudyInputError(
            f"{source}: task = {task!r}; expected one of {', '.join(task_names())}"
        )
    groups = data["groups"]
    _check_groups(groups, source)
    factors_in = data.get("factors", {})
    _check_factor_names(factors_in, task, source)
    factors = {n: _factor(source, n, factors_in[n]) for n in FACTORS if n in factors_in}
    spec = CampaignSpec(
        name=data.get("name", "campaign"),
        seed=_whole(source, "seed", data["seed"], 0),
        replicates=_whole(source, "replicates", data["replicates"], 1),
        task=task,
        trials_per_condition=_whole(
            source, "trials_per_condition", data.get("trials_per_condition", 1), 1
        ),
        groups=dict(groups),
        factors=factors,
        **_participants(data.get("participants"), source, task),
    )
    for scale in factors.get("group_scale", (1.0,)):
        for g, n in groups.items():
            if round(n * scale) < MIN_GROUP:
                raise StudyInputError(
                    f"{source}: groups.{g} = {n} x group_scale {scale:g} gives "
                    f"{round(n * scale)} participants; expected at least {MIN_GROUP} "
                    "(the fewest the paired tests take)"
                )
    return spec


def _check_groups(groups: dict[str, Any], source: str) -> None:
    """Groups with simulated participants, each a whole number of at least one."""
    if not groups:
        raise StudyInputError(f"{source}: [groups] is empty; expected e.g. novice = 8")
    for g, n in groups.items():
        if g not in DEFAULT_GROUPS:
            raise StudyInputError(
                f"{source}: groups.{g}; expected groups with simulated participants: "
                f"{', '.join(DEFAULT_GROUPS)}"
            )
        _whole(source, f"groups.{g}", n, 1)


def _check_factor_names(factors: dict[str, Any], task: str, source: str) -> None:
    """Known factors only, and only those the task's trials use."""
    the_task = get_task(task)
    for name in factors:
        if name not in FACTORS:
            raise StudyInputError(
                f"{source}: unknown factor {name!r}; expected any of {', '.join(FACTORS)}"
            )
        lacks = (
            "haptic dial"
            if name == "haptic_gain" and not the_task.has_dial
            else "master-follower link"
            if name.startswith("link_") and not the_task.has_link
            else None
        )
        if lacks:
            raise StudyInputError(
                f"{source}: factors.{name} with task = {task!r}, which has no {lacks}; "
                "expected only the factors its trials use"
            )
