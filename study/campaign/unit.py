"""One campaign unit: a whole simulated study at the physics level, and its VO-HV tests.

The study is what `study init` + `study participant add` + `study run` would make of
the unit's design, without the database: participants enrolled group after group with
codes P001, P002, ..., each given the counterbalanced order `next_order` gives it, its
blocks from `plan_blocks`, the simulated person `participant_traits` draws from the
study seed and its code, and each measured trial run on the same loop, phantom and
estimator with the seed `study run` gives that trial (first attempt), and the
participant model's effects (practice, fatigue, carry-over) at the trial's place among
the measured trials. Practice trials are not run: a simulated person's state in a trial
follows from its seed and that place, not from the trials run before it, so they
change no measured value.

The measures are the task's analysed measures as `study run` stores them
(`study.protocol.tasks`: completion time and, for LCCA, peak proximal and distal force;
for NOTES, peak demanded and tip force), averaged per participant and condition as
`participant_means` does, and tested with the analysis's own `compare_conditions`.
"""

from __future__ import annotations

import time
import zlib
from functools import lru_cache

import numpy as np
import pandas as pd

from study.analysis.comparisons import compare_conditions
from study.analysis.paired import hedges_g_av
from study.analysis.stats import ALPHA
from study.campaign.spec import CampaignSpec, Cell, study_seed
from study.protocol.default_estimator import load_estimator
from study.protocol.design import KNOWN_CONDITIONS, StudyDesign, next_order
from study.protocol.participant_effects import apply_effects, session_place
from study.protocol.roster import CODE_DIGITS, plan_blocks
from study.protocol.session import MAX_TRIAL_S, participant_traits
from study.protocol.tasks import get_task
from study.protocol.traits import ParticipantTraits
from study.protocol.trial_run import simulate_trial
from teleop_core.estimation.estimator import ForceEstimator
from teleop_core.loop.link import LinkParams


def measures(task: str) -> tuple[str, ...]:
    """The trial measures the analysis compares for `task`."""
    return get_task(task).analysed_measures


UNIT_COLUMNS = (
    "replicate",
    "group",
    "measure",
    "n",
    "mean_vo",
    "mean_hv",
    "effect",
    "p",
    "significant",
    "test",
    "p_holm",
    "seed",
)
"""A unit's rows (the factor columns go in front of them in results.csv)."""


@lru_cache(maxsize=1)
def _estimator() -> ForceEstimator:
    """The shipped estimator, loaded once per worker process."""

    return load_estimator()


def trial_seed(seed: int, code: str, block_index: int, trial_index: int) -> int:
    """The seed `study run` gives a measured trial's first attempt (session._run_trial)."""
    return zlib.crc32(f"{seed}/{code}/{block_index}/0/{trial_index}/1".encode())


def enrol(design: StudyDesign) -> list[tuple[str, str, tuple[str, ...]]]:
    """(code, group, condition order) of every participant, enrolled group by group."""
    people: list[tuple[str, str, tuple[str, ...]]] = []
    for group, n in design.groups.items():
        used: list[tuple[str, ...]] = []
        for _ in range(n):
            order = next_order(design, group, used)
            used.append(order)
            people.append((f"{design.code_prefix}{len(people) + 1:0{CODE_DIGITS}d}", group, order))
    return people


def run_trial(
    task: str,
    traits: ParticipantTraits,
    condition: str,
    seed: int,
    cell: Cell,
    context: object,
) -> dict[str, float]:
    """One measured trial's analysed measures (as `study run` stores them)."""
    v, the_task = cell.values, get_task(task)
    link = LinkParams(
        delay_s=v["link_delay_ms"] / 1e3, jitter_s=v["link_jitter_ms"] / 1e3, loss=v["link_loss"]
    )
    s = simulate_trial(
        the_task,
        traits,
        condition,
        seed,
        MAX_TRIAL_S,
        haptic_gain_n_m_per_n=v["haptic_gain"] if the_task.has_dial else None,
        estimator=_estimator() if the_task.has_dial else None,
        link=link,
        context=context,
    ).summary
    return {m: float(s[m]) for m in the_task.analysed_measures}


def simulate_study(spec: CampaignSpec, cell: Cell, replicate: int) -> pd.DataFrame:
    """Every measured trial of the unit: participant, group, condition, trial, MEASURES."""
    seed = study_seed(spec.seed, replicate)
    design = StudyDesign(
        name=spec.name,
        seed=seed,
        conditions=KNOWN_CONDITIONS,
        tasks=(spec.task,),
        trials_per_condition=spec.trials_per_condition,
        practice_trials=0,
        groups=spec.sizes(cell),
    )
    context = get_task(spec.task).session_context()
    model = spec.participant_model()
    effects = model.participant_effects if model is not None else ()
    rows = []
    for code, group, order in enrol(design):
        traits = participant_traits(seed, code, group, model)
        blocks = plan_blocks(design, order)
        conditions = [b["condition"] for b in blocks]
        for b, block in enumerate(blocks):
            for i in range(block["n_trials"]):
                s = trial_seed(seed, code, block["block_index"], i)
                place = session_place(conditions, b, i, block["n_trials"])
                person = apply_effects(traits, effects, place)
                values = run_trial(spec.task, person, block["condition"], s, cell, context)
                rows.append(
                    {
                        "participant": code,
                        "group": group,
                        "condition": block["condition"],
                        "trial": i + 1,
                        **values,
                    }
                )
    return pd.DataFrame(rows)


def compare_unit(trials: pd.DataFrame, task: str) -> pd.DataFrame:
    """The analysis's VO-HV test per group and measure on participant means.

    Columns: group, measure, n, mean_vo, mean_hv, effect (Hedges' g_av of HV - VO,
    whichever test the analysis picks), p (that test's), significant (p < ALPHA),
    test (paired_t or wilcoxon), p_holm (Holm across the groups of a measure).
    """
    means = trials.groupby(["participant", "group", "condition"], sort=False)[list(measures(task))]
    long = (
        means.mean()
        .reset_index()
        .melt(id_vars=["participant", "group", "condition"], var_name="measure", value_name="value")
    )
    long["task"] = task
    table, _ = compare_conditions(long)
    wide = long.pivot_table(
        index=["measure", "group", "participant"], columns="condition", values="value"
    )
    effects = {
        (m, g): hedges_g_av(w["VO"].to_numpy(float), w["HV"].to_numpy(float))
        for (m, g), w in wide.groupby(level=[0, 1])
    }
    out = table[["group", "measure", "n", "mean_vo", "mean_hv", "p", "test", "p_holm"]].copy()
    out["effect"] = [effects[(m, g)] for m, g in zip(out["measure"], out["group"], strict=True)]
    out["significant"] = out["p"] < ALPHA
    return out


def run_unit(spec: CampaignSpec, cell: Cell, replicate: int) -> tuple[pd.DataFrame, float]:
    """The unit's rows (UNIT_COLUMNS, groups and measures in the spec's order) and how
    long it took to compute, in seconds (kept apart: the rows must not depend on it)."""
    start = time.perf_counter()
    tested = compare_unit(simulate_study(spec, cell, replicate), spec.task)
    names = measures(spec.task)
    order = {key: k for k, key in enumerate((g, m) for g in spec.groups for m in names)}
    keys = [order[key] for key in zip(tested["group"], tested["measure"], strict=True)]
    tested = tested.iloc[np.argsort(keys, kind="stable")]
    tested.insert(0, "replicate", replicate)
    tested["seed"] = study_seed(spec.seed, replicate)
    rows = tested[list(UNIT_COLUMNS)].reset_index(drop=True)
    rows["n"] = rows["n"].astype("int64")
    rows["significant"] = rows["significant"].astype(bool)
    return rows, time.perf_counter() - start
