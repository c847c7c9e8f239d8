"""`study demo`: the default study, simulated from enrolment to the paper's figures.

Creates the study from the default design, enrols 20 outsiders, 8 novices and 8
experts, runs every session with simulated participants in two processes, fills in
their NASA-TLX (`simulated_tlx`: from each block's experience), and writes the
analysis and the figures.
"""

from __future__ import annotations

import json
import re
import zlib
from collections.abc import Callable

import numpy as np
import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.study import Participant, Study
from db.models.tlx import TlxResponse
from db.models.trial import Trial
from study.errors import StudyInputError
from study.protocol.demo_marks import COMPLETE, STARTED, demo_state, mark_demo
from study.protocol.design import TEMPLATE, StudyDesign, parse_design
from study.protocol.parallel import Workers, start_workers
from study.protocol.roster import add_participant, create_study
from study.protocol.simulated_tlx import (
    block_preference,
    block_ratings,
    pairwise_choices,
    person_offsets,
    person_preference,
)
from study.protocol.tlx import store_tlx
from teleop_core.progress import Progress, no_progress


def fill_tlx(db_url: str, study_seed: int, durable: bool = True) -> int:
    """A questionnaire for every block of every participant that has none; returns how
    many were stored.
    `durable=False`: commits not synced one by one (`db.engine.make_engine`)."""
    engine = open_database(db_url, create=False, durable=durable)
    stored = 0
    try:
        with Session(engine) as session:
            people = session.scalars(select(Participant).order_by(Participant.code)).all()
            trials = pd.DataFrame(
                [
                    (
                        t.participant_id,
                        t.task,
                        t.condition,
                        t.completion_time_s,
                        t.measure_values.get("wall_contacts", 0),
                        t.success,
                        (t.summary or {}).get("obstacles_seen", 0),
                        (t.summary or {}).get("obstacles_felt", 0),
                    )
                    for t in session.scalars(
                        select(Trial).where(Trial.status == "completed", Trial.practice.is_(False))
                    )
                ],
                columns=["pid", "task", "condition", "time", "contacts", "success", "seen", "felt"],
            )
            plan = [(p.id, p.code, [(b.task, b.condition) for b in p.blocks]) for p in people]
            filled = set(
                session.execute(
                    select(TlxResponse.participant_id, TlxResponse.task, TlxResponse.condition)
                ).all()
            )
        # each block's trials, in stored order (one pass, not a filter per block)
        by_block = {key: rows for key, rows in trials.groupby(["pid", "task", "condition"])}
        empty = trials.iloc[:0]
        for pid, code, blocks in plan:
            rng = np.random.default_rng([study_seed, zlib.crc32(code.encode()), 0x7A])
            offsets = person_offsets(rng)
            preference = person_preference(rng)
            for task, condition in blocks:
                chosen = pairwise_choices(study_seed, code, rng, block_preference(preference, rng))
                block = by_block.get((pid, task, condition), empty)
                ratings = block_ratings(
                    block["time"].tolist(),
                    block["contacts"].tolist(),
                    block["success"].tolist(),
                    rng,
                    offsets,
                    int(block["seen"].sum()),
                    int(block["felt"].sum()),
                )
                if (pid, task, condition) in filled:  # a demo continued: drawn, not stored
                    continue
                store_tlx(engine, code, task, condition, ratings, chosen)
                stored += 1
    finally:
        engine.dispose()
    return stored


def _run_sessions(workers: Workers, codes: list[str], progress: Progress) -> None:
    for k, (code, _) in enumerate(workers.run(codes), 1):
        progress(f"sessions: {k}/{len(codes)} participants ({code})")


QUICK = {
    "outsider = 20": "outsider = 2",
    "novice = 8": "novice = 2",
    "expert = 8": "expert = 2",
    "trials_per_condition = 3": "trials_per_condition = 1",
    "practice_trials = 1": "practice_trials = 0",
}
"""The default design shrunk to 2/2/2 participants and one trial per block."""


def run_demo(
    db_url: str,
    seed: int,
    jobs: int = 2,
    progress: Progress = no_progress,
    quick: bool = False,
    participants: str | None = None,
    sizes: dict[str, int] | None = None,
    trials_per_condition: int | None = None,
    notice: Callable[[str], None] | None = None,
    workers: Workers | None = None,
) -> None:
    """Create, enrol, run and fill in the questionnaires of the default study.

    `participants`: a fitted participant model (MODEL.json) the people are drawn from;
    `sizes` and `trials_per_condition` replace the default design's (a study of another
    size, e.g. for the participant fit's benchmark), with no practice trials. `notice`
    is told when the simulation loop is compiled (the first run after install).
    `workers`: the session workers to run them (`start_workers(db_url, jobs,
    participants=..., durable=False)`, started by the caller before this), else
    `jobs` processes started here.

    The database is new, or holds a demo stopped halfway (`check_resumable`), which is
    continued: the participants it had not enrolled are, each session goes on where it
    stopped (an interrupted trial is repeated), the questionnaires not yet filled in
    are. Audit rows mark the demo started (with its options) and complete, so a
    half-finished demo says so (`demo_state`). Its commits are not synced to the disk
    one by one (`durable=False` of `db.engine.make_engine`): a power cut can lose its
    last commits, which the run that continues it writes again. Its samples, one commit
    per second of trial time, each waited for a sync before."""
    text = TEMPLATE.replace("seed = 1 ", f"seed = {seed} ")
    for old, new in QUICK.items() if quick else ():
        text = text.replace(old, new)
    for group, n in (sizes or {}).items():
        text = re.sub(rf"^{group} = \d+", f"{group} = {n}", text, flags=re.M)
    if trials_per_condition is not None:
        text = re.sub(
            r"^trials_per_condition = \d+",
            f"trials_per_condition = {trials_per_condition}",
            text,
            flags=re.M,
        )
        text = re.sub(r"^practice_trials = \d+", "practice_trials = 0", text, flags=re.M)
    design = parse_design(text)
    engine = open_database(db_url, create=True, durable=False)
    try:
        if demo_state(engine) is None:
            create_study(engine, design, text)
            mark_demo(engine, STARTED, _options(seed, quick, sizes, trials_per_condition))
        codes = _enrolled(engine, design)
    finally:
        engine.dispose()
    if workers is None:
        with start_workers(
            db_url, jobs, participants=participants, notice=notice, durable=False
        ) as own:
            _run_sessions(own, codes, progress)
    else:
        _run_sessions(workers, codes, progress)
    progress("NASA-TLX")
    fill_tlx(db_url, design.seed, durable=False)
    engine = open_database(db_url, create=False, durable=False)
    try:
        mark_demo(engine, COMPLETE, "every session run and every questionnaire filled in")
    finally:
        engine.dispose()


def _options(
    seed: int, quick: bool, sizes: dict[str, int] | None, trials_per_condition: int | None
) -> str:

    return json.dumps(
        {"seed": seed, "quick": quick, "sizes": sizes, "trials_per_condition": trials_per_condition}
    )


def check_resumable(
    engine: Engine,
    seed: int,
    quick: bool,
    sizes: dict[str, int] | None = None,
    trials_per_condition: int | None = None,
) -> None:
    """StudyInputError unless the database is new, or holds an incomplete demo started
    with these options (then `run_demo` goes on with it)."""

    state = demo_state(engine)
    if state is None:
        with Session(engine) as session:
            other = session.scalar(select(Study.name).limit(1))
        if other is not None:
            raise StudyInputError(
                f"the database holds study {other!r}, not a demo; expected a new --out folder "
                "or --db"
            )
        return
    if state[0] == COMPLETE:
        raise StudyInputError(
            "the database holds a complete demo already; expected a new --out folder or --db"
        )
    given = _options(seed, quick, sizes, trials_per_condition)
    if state[1] != given:
        raise StudyInputError(
            f"the incomplete demo there was started with {state[1]}; expected the same "
            f"options to finish it, got {given}"
        )


def _enrolled(engine: Engine, design: StudyDesign) -> list[str]:
    """The demo's participant codes, enrolling those a stopped demo had not yet."""
    with Session(engine) as session:
        have = session.execute(select(Participant.group, Participant.code)).all()
    codes = [c for _, c in have]
    for group, n in design.groups.items():
        missing = n - sum(g == group for g, _ in have)
        codes += [add_participant(engine, group).code for _ in range(missing)]
    return codes
