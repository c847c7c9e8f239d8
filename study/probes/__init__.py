"""Probes: short psychophysical measurements before a task's first block, each telling
one trait of the participant model that the task's trials tell weakly.

A probe is one module plus a registry entry, as a task is (`study.protocol.tasks`):
the built-in probes are the modules in `BUILTIN`; an installed package adds one through
the entry point group `haptic_study.probes` (its object satisfies `base.Probe`).

- `base.py`: the `Probe` protocol, a stored trial, a trait's estimate;
- one module per probe (`force_threshold`, `reaction_time`, `stall_detection`,
  `aiming`, `comfort_torque`);
- `measure.py`: every probe's measurement model over a participant's trials, the hook
  the participant fit uses;
- `runner.py`: a participant's probes run with a responder (simulated, keyboard,
  hardware); `store.py`: the trials in the database.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from study.errors import StudyInputError

if TYPE_CHECKING:
    from study.probes.base import Probe

ENTRY_POINT_GROUP = "haptic_study.probes"
BUILTIN = (
    "study.probes.reaction_time",
    "study.probes.force_threshold",
    "study.probes.stall_detection",
    "study.probes.aiming",
    "study.probes.comfort_torque",
)
BUILTIN_NAMES = tuple(module.rsplit(".", 1)[1] for module in BUILTIN)
"""A built-in probe's name is its module's: a design naming one is checked without
importing the probes' numerics (`study tui` reads the design before numpy loads)."""
_REGISTRY: dict[str, Probe] = {}
_LOADED = _ENTRY_POINTS_LOADED = False


def register(probe: Probe) -> Probe:
    """Add `probe` to the registry (replacing one of the same name); returns it."""
    # here, not at the top: importing study.probes.base imports this module
    from study.probes.base import Probe

    name = getattr(probe, "name", "")
    if not name or not name.isidentifier() or len(name) > 32:
        raise ValueError(f"probe name {name!r}; expected an identifier of at most 32 characters")
    if not isinstance(probe, Probe):
        raise ValueError(f"probe {name}: does not have every member of study.probes.base.Probe")
    _REGISTRY[name] = probe
    return probe


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)


def _load(entry_points_too: bool = False) -> None:
    global _LOADED, _ENTRY_POINTS_LOADED
    if not _LOADED:
        _LOADED = True
        for module, name in zip(BUILTIN, BUILTIN_NAMES, strict=True):
            probe = importlib.import_module(module).PROBE
            if probe.name != name:  # pragma: no cover - a built-in named apart from its module
                raise RuntimeError(f"{module}.PROBE is named {probe.name!r}, not {name!r}")
            register(probe)
    if entry_points_too and not _ENTRY_POINTS_LOADED:
        _ENTRY_POINTS_LOADED = True
        from importlib.metadata import entry_points

        for entry in entry_points(group=ENTRY_POINT_GROUP):
            register(entry.load())


def probe_names() -> tuple[str, ...]:
    """The probes a design may name: the built-in ones first, then those registered."""
    _load(entry_points_too=True)
    return tuple(_REGISTRY)


def is_probe(name: str) -> bool:
    if name in BUILTIN_NAMES:
        return True
    _load()
    if name not in _REGISTRY:
        _load(entry_points_too=True)
    return name in _REGISTRY


def get_probe(name: str) -> Probe:
    """The probe called `name`; an unknown name gets one line listing the known ones."""
    if not is_probe(name):
        raise StudyInputError(f"probe {name!r}; expected one of {', '.join(probe_names())}")
    _load()  # a built-in name is known before its module is imported
    return _REGISTRY[name]


def probes() -> tuple[Probe, ...]:
    _load(entry_points_too=True)
    return tuple(_REGISTRY.values())
