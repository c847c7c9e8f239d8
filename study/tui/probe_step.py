"""The session flow's probe step in the terminal app: the checklist, then the probes the
design names before this block, then the block.

`due_probes` says which of the design's probes a participant still owes before a block;
`run_due_probes` runs them when the session's driver is the simulated person (in the
run screen's worker thread, before the trial: `trial_runner.TrialRun.run`) and
otherwise returns one line naming the command: the keyboard and the dial answer probes
through `study probe run`, whose responders (`study.probes.runner`) read a terminal line
or the dial unit. The line is kept on the run (`TrialRun.probe_line`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.trial import Trial
from study.protocol.observer import SessionObserver
from study.protocol.roster import find_participant, find_study, load_study

if TYPE_CHECKING:
    from study.protocol.design import StudyDesign


def due_probes(engine: Engine, code: str, design: StudyDesign | None = None) -> list[str]:
    """The design's probes `code` has not stored, if the next block is the one they run
    before or a later one; empty otherwise. `design`: the study's, already read (else
    read here)."""
    # lazy: study.probes.store (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.probes.store import stored_probes

    with Session(engine) as session:
        if design is None:
            study, design = load_study(session)
        else:
            study = find_study(session)
        if not design.probes:
            return []
        participant = find_participant(session, study, code)
        started = set(
            session.scalars(select(Trial.block_index).where(Trial.participant_id == participant.id))
        )
        pid = participant.id
    # blocks are numbered from 0 in the schedule, from 1 in the design's before_block
    if len(started) < design.probes_before_block - 1:
        return []
    done = stored_probes(engine, pid)
    return [name for name in design.probes if name not in done]


def run_due_probes(
    engine: Engine,
    code: str,
    driver_kind: str,
    observer: SessionObserver | None = None,
    design: StudyDesign | None = None,
) -> str | None:
    """Run `code`'s due probes with the simulated person; a line for the screen (None
    when none were due). `observer` is told each probe trial; `design` as `due_probes`."""
    due = due_probes(engine, code, design)
    if not due:
        return None
    if driver_kind != "simulated":
        return (
            f"{code} has probes due before this block ({', '.join(due)}): run "
            f"`study probe run --participant {code} --driver {driver_kind}`"
        )
    # lazy: study.probes.store (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.probes.store import run_participant_probes

    stored = run_participant_probes(engine, code, only=tuple(due), observer=observer)
    return f"{code}: probes stored ({', '.join(f'{k} {n}' for k, n in stored.items())})"
