"""Study designs: the TOML file a researcher writes, validated into a `StudyDesign`.

Every problem is reported as one line naming the key, the value and what was expected
(`StudyInputError`), before anything is written. Defaults follow [endovascular], IV-D: 20
engineering outsiders, 8 novice doctors, 8 expert physicians; conditions VO and HV; the
LCCA task.

Counterbalancing (`condition_orders`): with two conditions the orders AB and BA; with
more, a balanced Latin square (Williams design: each condition once in every position
and, over the square, before each other condition equally often; k rows for an even
number of conditions, 2k for an odd one). Participants of a group get the order that
group has used least so far (`next_order`), so after any number of participants the
orders' counts differ by at most one.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, field
from typing import Any

from db.tlx_subscales import TLX_SUBSCALES
from study.errors import StudyInputError
from study.probes import is_probe, probe_names
from study.protocol.design_sensors import SensorSettings, predicate_problem, sensor_settings
from study.protocol.study_rows import measure_columns
from study.protocol.tasks import is_task, not_installed
from study.protocol.tasks.declarations import MAX_HAPTIC_GAIN_N_M_PER_N

KNOWN_CONDITIONS = ("VO", "HV")
MAX_TRIAL_S = 180.0
"""A trial ends unsuccessfully after this long (the session runner's limit), s."""
MAX_SEED = 2**31 - 1
"""Seeds are stored in an INTEGER column (32 bits on PostgreSQL) and fed to numpy (>= 0)."""
MAX_TRIALS_PER_CONDITION = 100
MAX_PRACTICE_TRIALS = 20
MAX_GROUP_SIZE = 1000
MAX_BREAK_S = 3600.0
"""Sane sizes (2**63 trials, a group of 1e12 and a break of inf are refused):
far above any lab study, far below what breaks storage or a schedule."""
MAX_GROUP_CHARS = 32
MAX_GROUPS = 12
"""The most experience groups a design may have (the paper has three; every analysis
compares them pairwise and draws one panel each)."""
MAX_NAME_CHARS = 200
"""Column widths of `participants.group` and `studies.name` (PostgreSQL enforces them)."""
DEFAULT_GROUPS = ("outsider", "novice", "expert")
"""The paper's experience groups ([endovascular], IV-D), the simulated participants' groups."""

TEMPLATE = """\
# A haptic-teleoperation user study ([endovascular], IV-D). `study init --design THIS_FILE`.

name = "LCCA navigation, VO vs HV"
seed = 1                       # seeds counterbalancing ties and simulated participants

conditions = ["VO", "HV"]      # Visual-Only, Haptic-Visual
tasks = ["lcca"]               # "lcca" (guidewire into the LCCA), "notes" (endoscopy)
trials_per_condition = 3       # measured trials in each task x condition block
practice_trials = 1            # unmeasured trials before them
counterbalancing = "AB/BA"     # two conditions; with more use "latin-square"
break_s = 120                  # planned rest after each block, seconds
tlx_before_next_block = true   # a block's NASA-TLX is due before the next block starts
code_prefix = "P"              # participant codes: P001, P002, ...

[haptic_gain_n_m_per_n]        # the dial's torque per newton of estimated force (LCCA)
HV = 0.02                      # the paper's gain ([endovascular]); VO renders nothing (0)

[probes]                       # short measurements before a block: `study probe run`
before_block = 1               # the block they run before (1: before the first)
force_threshold = 60           # trials of each probe: force-discrimination threshold (QUEST+)
reaction_time = 20             # simple reaction time
stall_detection = 20           # time to see that the tip has stopped
aiming = 30                    # turning the tip towards a target
comfort_torque = 8             # resistance on the dial the participant accepts

[groups]                       # experience groups and how many participants each
outsider = 20                  # engineering outsiders
novice = 8                     # novice doctors
expert = 8                     # expert interventional physicians
"""

_KEYS: dict[str, type | tuple[type, ...]] = {
    "name": str,
    "seed": int,
    "conditions": list,
    "tasks": list,
    "trials_per_condition": int,
    "practice_trials": int,
    "counterbalancing": str,
    "break_s": (int, float),
    "tlx_before_next_block": bool,
    "code_prefix": str,
    "groups": dict,
    "haptic_gain_n_m_per_n": dict,
    "lsl": dict,
    "sensors": dict,
    "probes": dict,
    "analysis": dict,
}
_KIND_WORDS: dict[type | tuple[type, ...], str] = {
    bool: "true or false",
    int: "a whole number",
    str: 'text in quotes, e.g. "x"',
    list: "a list, e.g. [...]",
    dict: "a table",
}
MAX_LSL_STREAMS = 16
MAX_PREDICATE_CHARS = 500
MAX_PROBE_TRIALS = 200
"""Far above any probe's need (an adaptive threshold settles in 40-80 trials)."""


@dataclass(frozen=True)
class LslSettings:
    """The design's `[lsl]` table: the lab's other instruments (`study.lsl`)."""

    publish: bool = False
    """Publish the session's markers and each trial's samples as LSL streams."""
    record: tuple[str, ...] = ()
    """LSL predicates (`type='EMG'`, `name='Tobii'`) of the streams to record during
    trials, each stored with its trial."""
    plot: tuple[str, ...] = ()
    """Recorded streams (by name or type) drawn in the trial figure."""

    def to_dict(self) -> dict[str, Any]:
        return {"publish": self.publish, "record": list(self.record), "plot": list(self.plot)}


@dataclass(frozen=True)
class AnalysisSettings:
    """The design's `[analysis]` table: the equivalence bounds of the TOST."""

    equivalence_fraction: float | None = None
    """Bound as a fraction of each group's VO mean, for every measure not in
    `equivalence_bounds`; None: only those."""
    equivalence_bounds: dict[str, float] = field(default_factory=dict)
    """Measure name -> bound in the measure's unit."""

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.equivalence_fraction is not None:
            out["equivalence_fraction"] = self.equivalence_fraction
        if self.equivalence_bounds:
            out["equivalence_bounds"] = dict(self.equivalence_bounds)
        return out


@dataclass(frozen=True)
class StudyDesign:
    name: str = "LCCA navigation, VO vs HV"
    seed: int = 1
    conditions: tuple[str, ...] = KNOWN_CONDITIONS
    tasks: tuple[str, ...] = ("lcca",)
    trials_per_condition: int = 3
    practice_trials: int = 1
    counterbalancing: str = "AB/BA"
    break_s: float = 120.0
    tlx_before_next_block: bool = True
    """The session flow: a finished block's questionnaire before the next block starts
    (the terminal app holds the next block until it is stored)."""
    code_prefix: str = "P"
    groups: dict[str, int] = field(
        default_factory=lambda: {"outsider": 20, "novice": 8, "expert": 8}
    )
    haptic_gain_n_m_per_n: dict[str, float] = field(default_factory=dict)
    """Per condition, the haptic dial's gain (tasks with a dial); a condition not listed
    uses the paper's (`teleop_core.master.params.HapticParams`); VO renders none."""
    probes: dict[str, int] = field(default_factory=dict)
    """Probe name (`study.probes`) -> its trials; empty: the study runs no probes."""
    probes_before_block: int = 1
    """The block (1-based) the probes run before."""

    lsl: LslSettings = field(default_factory=LslSettings)
    """The `[lsl]` table (streams published and recorded); off by default."""
    analysis: AnalysisSettings = field(default_factory=AnalysisSettings)
    """The `[analysis]` table (equivalence bounds); none by default."""
    sensors: SensorSettings = field(default_factory=SensorSettings)
    """The `[sensors]` table (a real follower's force sensors); none by default."""

    def haptic_gain_for(self, condition: str) -> float | None:
        """The dial's gain in `condition`; None: the task's default (the paper's)."""
        return self.haptic_gain_n_m_per_n.get(condition)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["conditions"] = list(self.conditions)
        data["tasks"] = list(self.tasks)
        data["haptic_gain_n_m_per_n"] = dict(self.haptic_gain_n_m_per_n)
        data["lsl"] = self.lsl.to_dict()
        if self.lsl == LslSettings():  # designs without the table read as before
            del data["lsl"]
        data["analysis"] = self.analysis.to_dict()
        if not data["analysis"]:
            del data["analysis"]
        data["sensors"] = self.sensors.to_dict()
        if not data["sensors"]:
            del data["sensors"]
        data["probes"] = {"before_block": self.probes_before_block, **self.probes}
        del data["probes_before_block"]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> StudyDesign:
        return _validate(data)

    @property
    def orders(self) -> list[tuple[str, ...]]:
        return condition_orders(self.conditions, self.counterbalancing)


def parse_design(text: str, source: str = "design") -> StudyDesign:
    """Parse and validate a TOML design."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyInputError(f"{source} is not valid TOML: {exc}") from None
    return _validate(data, source)


def _validate(data: dict[str, Any], source: str = "design") -> StudyDesign:
    """The design that `data` (a parsed design file) describes; StudyInputError naming the
    first value out of place, checked in the file's reading order."""
    _check_keys(data, source)
    d = StudyDesign()
    conditions = tuple(data.get("conditions", d.conditions))
    tasks = tuple(data.get("tasks", d.tasks))
    groups = dict(data.get("groups", d.groups))
    _check_conditions(conditions, source)
    _check_tasks(tasks, source)
    _check_groups(groups, source)
    _check_sizes(data, d, source)
    prefix = data.get("code_prefix", d.code_prefix)
    scheme = data.get("counterbalancing", d.counterbalancing)
    gains = _haptic_gains(data.get("haptic_gain_n_m_per_n", {}), conditions, source)
    probes, before = _probes(data.get("probes", {}), len(tasks) * len(conditions), source)
    design = StudyDesign(
        name=data.get("name", d.name),
        seed=data.get("seed", d.seed),
        conditions=conditions,
        tasks=tasks,
        trials_per_condition=data.get("trials_per_condition", d.trials_per_condition),
        practice_trials=data.get("practice_trials", d.practice_trials),
        counterbalancing=scheme,
        break_s=float(data.get("break_s", d.break_s)),
        tlx_before_next_block=data.get("tlx_before_next_block", d.tlx_before_next_block),
        code_prefix=prefix,
        groups=groups,
        haptic_gain_n_m_per_n=gains,
        lsl=_lsl_settings(data.get("lsl", {}), source),
        probes=probes,
        probes_before_block=before,
        analysis=_analysis_settings(data.get("analysis", {}), tasks, source),
        sensors=sensor_settings(data.get("sensors", {}), source),
    )
    condition_orders(conditions, scheme, source)  # refuses a scheme that does not fit
    return design


def _check_keys(data: dict[str, Any], source: str) -> None:
    """Known keys only, each of its kind."""
    if not data:  # an empty file would silently be the default study
        raise StudyInputError(
            f"{source} is empty; expected a study design (`study design template` prints one)"
        )
    unknown = sorted(set(data) - set(_KEYS))
    if unknown:
        raise StudyInputError(
            f"{source}: unknown key {unknown[0]!r}; expected one of {', '.join(sorted(_KEYS))}"
        )
    for key, kind in _KEYS.items():
        # TOML's true is a Python bool, which is an int too: only a key of kind bool takes it
        if key in data and (
            not isinstance(data[key], kind) or (kind is not bool and isinstance(data[key], bool))
        ):
            expected = _KIND_WORDS.get(kind, "a number")
            raise StudyInputError(f"{source}: {key} = {data[key]!r}; expected {expected}")


def _check_conditions(conditions: tuple[str, ...], source: str) -> None:
    for c in conditions:
        if c not in KNOWN_CONDITIONS:
            raise StudyInputError(
                f"{source}: condition {c!r}; expected {' or '.join(KNOWN_CONDITIONS)}"
            )
    if len(set(conditions)) != len(conditions) or len(conditions) < 2:
        raise StudyInputError(
            f"{source}: conditions = {list(conditions)}; expected at least two, each once"
        )


def _check_tasks(tasks: tuple[str, ...], source: str) -> None:

    for t in tasks:
        if not is_task(t):
            raise StudyInputError(f"{source}: {not_installed(t)}")
    if not tasks or len(set(tasks)) != len(tasks):
        raise StudyInputError(f"{source}: tasks = {list(tasks)}; expected at least one, each once")


def _check_groups(groups: dict[str, Any], source: str) -> None:
    if not groups:
        raise StudyInputError(f"{source}: [groups] is empty; expected e.g. novice = 8")
    if len(groups) > MAX_GROUPS:
        raise StudyInputError(
            f"{source}: [groups] has {len(groups)} groups; expected 1 to {MAX_GROUPS}"
        )
    seen: dict[str, str] = {}
    for g, n in groups.items():
        other = seen.setdefault(g.casefold(), g)
        if other != g:
            raise StudyInputError(
                f"{source}: groups {other!r} and {g!r} differ only in case; expected each "
                "group once (one name, one group in every table and figure)"
            )
        if not (0 < len(g) <= MAX_GROUP_CHARS and g.isprintable() and g.strip() == g):
            raise StudyInputError(
                f"{source}: group name {g!r}; expected 1-{MAX_GROUP_CHARS} printable "
                "characters without surrounding spaces"
            )
        if not (isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_GROUP_SIZE):
            raise StudyInputError(
                f"{source}: groups.{g} = {n!r}; expected a whole number from 1 to {MAX_GROUP_SIZE}"
            )


def _check_sizes(data: dict[str, Any], d: StudyDesign, source: str) -> None:
    """The counts, the seed, the break, the name and the code prefix within bounds."""
    for key, low, high in (
        ("trials_per_condition", 1, MAX_TRIALS_PER_CONDITION),
        ("practice_trials", 0, MAX_PRACTICE_TRIALS),
        ("seed", 0, MAX_SEED),
    ):
        value = data.get(key, getattr(d, key))
        if not low <= value <= high:
            raise StudyInputError(f"{source}: {key} = {value!r}; expected {low} to {high}")
    break_s = data.get("break_s", d.break_s)
    if not (math.isfinite(break_s) and 0 <= break_s <= MAX_BREAK_S):
        raise StudyInputError(f"{source}: break_s = {break_s!r}; expected 0 to {MAX_BREAK_S:g} s")
    name = data.get("name", d.name)
    if not (0 < len(name.strip()) and len(name) <= MAX_NAME_CHARS and name.isprintable()):
        raise StudyInputError(
            f"{source}: name = {name!r}; expected 1-{MAX_NAME_CHARS} printable characters"
        )
    prefix = data.get("code_prefix", d.code_prefix)
    if not (1 <= len(prefix) <= 4 and prefix.isascii() and prefix.isalpha() and prefix.isupper()):
        raise StudyInputError(
            f"{source}: code_prefix = {prefix!r}; expected 1-4 capital letters A-Z, e.g. P"
        )


def _haptic_gains(
    table: dict[str, Any], conditions: tuple[str, ...], source: str
) -> dict[str, float]:
    gains = {}
    for condition, gain in table.items():
        key = f"{source}: haptic_gain_n_m_per_n.{condition}"
        if condition not in conditions:
            raise StudyInputError(
                f"{key} names no condition of the design; expected one of {', '.join(conditions)}"
            )
        if isinstance(gain, bool) or not isinstance(gain, int | float):
            raise StudyInputError(f"{key} = {gain!r}; expected a number (N m/N)")
        if condition == "VO" and gain != 0:
            raise StudyInputError(f"{key} = {gain!r}; expected 0 (Visual-Only renders no force)")
        if not (math.isfinite(gain) and 0 <= gain <= MAX_HAPTIC_GAIN_N_M_PER_N):
            raise StudyInputError(
                f"{key} = {gain!r}; expected 0 to {MAX_HAPTIC_GAIN_N_M_PER_N:g} N m/N"
            )
        gains[condition] = float(gain)
    return gains


def _lsl_settings(table: dict[str, Any], source: str) -> LslSettings:
    known = ("publish", "record", "plot")
    for key in table:
        if key not in known:
            raise StudyInputError(
                f"{source}: unknown key lsl.{key}; expected one of {', '.join(known)}"
            )
    publish = table.get("publish", False)
    if not isinstance(publish, bool):
        raise StudyInputError(f"{source}: lsl.publish = {publish!r}; expected true or false")
    lists = {}
    for key, example in (("record", "[\"type='EMG'\"]"), ("plot", '["EMG"]')):
        value = table.get(key, [])
        if not (
            isinstance(value, list)
            and len(value) <= MAX_LSL_STREAMS
            and all(
                isinstance(v, str)
                and 0 < len(v.strip())
                and len(v) <= MAX_PREDICATE_CHARS
                and v.isprintable()
                for v in value
            )
        ):
            raise StudyInputError(
                f"{source}: lsl.{key} = {value!r}; expected a list of at most "
                f"{MAX_LSL_STREAMS} non-empty strings, e.g. {example}"
            )
        lists[key] = tuple(value)
    for query in lists["record"]:
        problem = predicate_problem(query)
        if problem:
            raise StudyInputError(
                f"{source}: lsl.record query {query!r} has {problem}; expected an LSL "
                "predicate such as type='EMG' or name='Glove' and type='Force'"
            )
    return LslSettings(publish, lists["record"], lists["plot"])


MAX_EQUIVALENCE_FRACTION = 1.0
"""An equivalence bound above the VO mean itself would call any difference equivalent."""


def _analysis_settings(
    table: dict[str, Any], tasks: tuple[str, ...], source: str
) -> AnalysisSettings:
    """[analysis]: the TOST bounds, or one line naming the value out of place."""
    known = ("equivalence_fraction", "equivalence_bounds")
    for key in table:
        if key not in known:
            raise StudyInputError(
                f"{source}: unknown key analysis.{key}; expected one of {', '.join(known)}"
            )
    fraction = table.get("equivalence_fraction")
    if fraction is not None and not (
        isinstance(fraction, int | float)
        and not isinstance(fraction, bool)
        and 0 < fraction <= MAX_EQUIVALENCE_FRACTION
    ):
        raise StudyInputError(
            f"{source}: analysis.equivalence_fraction = {fraction!r}; expected a number "
            f"above 0 and at most {MAX_EQUIVALENCE_FRACTION:g} (of the VO mean)"
        )
    bounds = table.get("equivalence_bounds", {})
    if not isinstance(bounds, dict):
        raise StudyInputError(
            f"{source}: analysis.equivalence_bounds = {bounds!r}; expected a table "
            "of measure = bound, e.g. completion_time_s = 10.0"
        )
    measures = _bounded_measures(tasks)
    out = {}
    for measure, bound in bounds.items():
        key = f"{source}: analysis.equivalence_bounds.{measure}"
        if measure not in measures:
            raise StudyInputError(
                f"{key} names no analysed measure; expected one of {', '.join(measures)}"
            )
        if (
            isinstance(bound, bool)
            or not isinstance(bound, int | float)
            or not (math.isfinite(bound) and bound > 0)
        ):
            raise StudyInputError(
                f"{key} = {bound!r}; expected a number above 0 (the measure's unit)"
            )
        out[measure] = float(bound)
    return AnalysisSettings(None if fraction is None else float(fraction), out)


def _bounded_measures(tasks: tuple[str, ...]) -> list[str]:
    """The measures a design's TOST may bound: its tasks' analysed ones and the TLX."""

    tlx = ["tlx_raw", "tlx_weighted", *(f"tlx_{s}" for s in TLX_SUBSCALES)]
    return [*measure_columns(tasks, analysed_only=True), *tlx]


def _probes(table: dict[str, Any], blocks: int, source: str) -> tuple[dict[str, int], int]:
    """[probes]: each probe's trials and the block they run before, or one line."""

    probes, before = {}, 1
    for key, value in table.items():
        where = f"{source}: probes.{key}"
        whole = isinstance(value, int) and not isinstance(value, bool)
        if key == "before_block":
            if not (whole and 1 <= value <= blocks):
                raise StudyInputError(
                    f"{where} = {value!r}; expected a block number from 1 to {blocks}"
                )
            before = value
            continue
        if not is_probe(key):
            raise StudyInputError(
                f"{where} names no probe; expected before_block or one of "
                f"{', '.join(probe_names())}"
            )
        if not (whole and 1 <= value <= MAX_PROBE_TRIALS):
            raise StudyInputError(
                f"{where} = {value!r}; expected a whole number of trials from 1 to "
                f"{MAX_PROBE_TRIALS}"
            )
        probes[key] = value
    return probes, before


def williams_square(n: int) -> list[list[int]]:
    """Balanced Latin square rows for n treatments (2n rows when n is odd)."""
    # first row 0, 1, n-1, 2, n-2, ...; row r adds r (mod n)
    first, low, high = [0], 1, n - 1
    while len(first) < n:
        first.append(low)
        low += 1
        if len(first) < n:
            first.append(high)
            high -= 1
    rows = [[(x + r) % n for x in first] for r in range(n)]
    if n % 2:
        rows += [row[::-1] for row in rows]
    return rows


def condition_orders(
    conditions: tuple[str, ...], scheme: str, source: str = "design"
) -> list[tuple[str, ...]]:
    """The orders participants are assigned to."""
    if scheme == "AB/BA":
        if len(conditions) != 2:
            raise StudyInputError(
                f"{source}: counterbalancing = 'AB/BA' with {len(conditions)} conditions; "
                "expected two conditions, or 'latin-square'"
            )
        return [tuple(conditions), tuple(reversed(conditions))]
    if scheme == "latin-square":
        return [tuple(conditions[i] for i in row) for row in williams_square(len(conditions))]
    raise StudyInputError(
        f"{source}: counterbalancing = {scheme!r}; expected 'AB/BA' or 'latin-square'"
    )


def next_order(design: StudyDesign, group: str, used: list[tuple[str, ...]]) -> tuple[str, ...]:
    """The order for the next participant of `group`, given the orders its members have.

    The least used order; ties are broken by a seeded shuffle of the orders that is
    fixed per group and per round, so the plan is reproducible from the design's seed.
    """
    orders = design.orders
    counts = [sum(1 for u in used if tuple(u) == o) for o in orders]
    least = min(counts)
    candidates = [i for i, c in enumerate(counts) if c == least]
    import numpy as np  # here, not at the top: `study tui` reads designs before numpy loads

    rng = np.random.default_rng([design.seed, sorted(design.groups).index(group), least])
    preference = rng.permutation(len(orders)).tolist()
    best = min(candidates, key=preference.index)
    return orders[best]
