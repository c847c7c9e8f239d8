"""A fitted participant model (MODEL.json): the trait distributions the simulated people
are drawn from instead of the hand-set `participants.PROFILES`.

`study participants fit` writes MODEL.json (`study.analysis.participant_fit`); `study
simulate`, `study run`, `study demo`, `study power` and campaigns read it here. Reading
owns the validation, so that every command refuses a bad file with the same one line
(`StudyInputError`, exit status 2) before anything is simulated or written.

The file's `groups` hold, per experience group and trait, `mean` and `sd` (SI units, the
trait names of `ParticipantTraits`); a draw is the group's normal clipped into the
trait's range (`participants.TRAIT_BOUNDS`), as for the hand-set profiles. Its
`participant_effects` (practice, fatigue, carry-over, `participant_effects`) change the
drawn person over the session, in every simulation drawn from the model. Its
`data_source` (`measured`, `simulated` or `mixed`) says what the model was fitted to:
a model fitted to simulated trials is an assumption checked against itself, not a
description of people, and every output drawn with it says which it was.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from study.errors import StudyInputError
from study.protocol.participant_effects import ParticipantEffect, effect_from_dict
from study.protocol.traits import (
    TRAIT_BOUNDS,
    TRAITS,
    GroupProfile,
    ParticipantTraits,
    draw_traits,
)

FORMAT = "haptic-study participant model"
"""MODEL.json's `format` value."""
DATA_SOURCES = ("measured", "simulated", "mixed")


@dataclass(frozen=True)
class ParticipantModel:
    """Trait distributions per group, read from MODEL.json."""

    task: str
    """The task whose trials it was fitted to."""
    profiles: dict[str, GroupProfile]
    data_source: str
    """`measured`, `simulated` or `mixed`: what the fitted trials were."""
    source: str
    """Where it was read from (a path), for messages."""
    digest: str
    """sha256 of the file's bytes (first 12 hex digits): which model, in the outputs."""
    effects: dict[str, dict[str, dict[str, float]]]
    """group -> measure -> {effect, correlation}: the standardised HV - VO effect and the
    VO-HV correlation of participant means that the fitted model simulates (for
    `study power`)."""
    participant_effects: tuple[ParticipantEffect, ...] = ()
    """The effects the fit added (practice, fatigue, carry-over): every trial drawn from
    the model carries them (`participant_effects.apply_effects`)."""

    def draw(self, group: str, rng: np.random.Generator) -> ParticipantTraits:
        if group not in self.profiles:
            raise StudyInputError(
                f"group {group!r} is not in the participant model {self.source}; expected "
                f"one of {', '.join(self.profiles)}"
            )
        return draw_traits(group, rng, self.profiles)

    def label(self) -> str:
        """One phrase for printed lines: which model, fitted to what."""
        return (
            f"participant model {self.source} (fitted to {self.data_source} trials, {self.digest})"
        )


def model_from_dict(data: Any, source: str, digest: str = "") -> ParticipantModel:
    """A `ParticipantModel` from MODEL.json's parsed content, or one line."""
    where = f"participant model {source}"
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise StudyInputError(
            f'{where}: no "format": "{FORMAT}"; expected a MODEL.json '
            "written by `study participants fit`"
        )
    task = data.get("task")
    if not isinstance(task, str):
        raise StudyInputError(f"{where}: task = {task!r}; expected a task name")
    if data.get("data_source") not in DATA_SOURCES:
        raise StudyInputError(
            f"{where}: data_source = {data.get('data_source')!r}; expected "
            f"one of {', '.join(DATA_SOURCES)}"
        )
    groups = data.get("groups")
    if not isinstance(groups, dict) or not groups:
        raise StudyInputError(f"{where}: groups = {groups!r}; expected an object of groups")
    profiles = {}
    for group, traits in groups.items():
        if not isinstance(traits, dict):
            raise StudyInputError(
                f"{where}: groups.{group} = {traits!r}; expected an object of traits"
            )
        missing = [t for t in TRAITS if t not in traits]
        if missing:
            raise StudyInputError(
                f"{where}: groups.{group} lacks {missing[0]!r}; expected "
                f"every trait: {', '.join(TRAITS)}"
            )
        values = {}
        for trait in TRAITS:
            values[trait] = _mean_sd(where, f"groups.{group}.{trait}", traits[trait], trait)
        profiles[group] = GroupProfile(**values)
    effects = data.get("effects", {})
    if not isinstance(effects, dict):
        raise StudyInputError(f"{where}: effects = {effects!r}; expected an object")
    listed = data.get("participant_effects", [])
    if not isinstance(listed, list):
        raise StudyInputError(f"{where}: participant_effects = {listed!r}; expected a list")
    added = [
        effect_from_dict(e, f"{where}: participant_effects[{i}]") for i, e in enumerate(listed)
    ]
    return ParticipantModel(
        task,
        profiles,
        data["data_source"],
        source,
        digest,
        effects,
        tuple(e for e in added if e is not None),
    )


def _finite(where: str, key: str, value: object) -> int | float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise StudyInputError(f"{where}: {key} = {value!r}; expected a finite number")
    return value


def _mean_sd(where: str, key: str, value: Any, trait: str) -> tuple[float, float]:
    lo, hi = TRAIT_BOUNDS[trait]
    if not isinstance(value, dict):
        raise StudyInputError(f'{where}: {key} = {value!r}; expected {{"mean": ..., "sd": ...}}')
    mean, sd = (_finite(where, f"{key}.{name}", value.get(name)) for name in ("mean", "sd"))
    if not lo <= mean <= hi:
        raise StudyInputError(
            f"{where}: {key}.mean = {mean!r}; expected a value in [{lo:g}, {hi:g}]"
        )
    if sd < 0:
        raise StudyInputError(f"{where}: {key}.sd = {sd!r}; expected a value >= 0")
    return float(mean), float(sd)


def load_model(path: Path | str, task: str | None = None) -> ParticipantModel:
    """MODEL.json at `path`; with `task`, refused unless it was fitted to that task."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise StudyInputError(
            f"participant model {path}: cannot be read "
            f"({exc.strerror or exc}); expected a MODEL.json file"
        ) from None
    try:
        data = json.loads(raw)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise StudyInputError(
            f"participant model {path} is not valid JSON ({exc}); expected "
            "a MODEL.json written by `study participants fit`"
        ) from None
    model = model_from_dict(data, str(path), hashlib.sha256(raw).hexdigest()[:12])
    if task is not None and model.task != task:
        raise StudyInputError(
            f"participant model {path} was fitted to the {model.task} task; "
            f"expected one fitted to {task}"
        )
    return model
