"""A participant's probe trials in the database: run and stored, read back as a frame.

Service functions own the queries (the CLI and the TUI call these). A participant's
probes are stored probe by probe, each in one transaction, so a crash loses at most the
probe that was running, never half of one; a probe already stored is not run again.
"""

from __future__ import annotations

import zlib
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.engine import write_transaction
from db.models.probe import ProbeTrial as ProbeTrialRow
from db.models.study import Participant
from study.errors import StudyInputError
from study.probes.base import ProbeTrial
from study.probes.runner import Responder, SimulatedResponder, run_probe
from study.protocol.design import StudyDesign
from study.protocol.observer import SessionObserver
from study.protocol.roster import find_participant, load_study
from teleop_core.progress import Progress, no_progress

PROBE_COLUMNS = (
    "participant",
    "group",
    "probe",
    "trial_index",
    "stimulus",
    "response",
    "correct",
    "context",
    "driver",
)


def probe_context(design: StudyDesign) -> dict[str, float]:
    """The settings every probe trial of the study runs with: the dial's HV gain (the
    paper's when the design names none)."""
    # lazy: teleop_core.master.params costs 4 ms at start-up
    from teleop_core.master.params import HapticParams

    gain = design.haptic_gain_for("HV")
    return {"gain_n_m_per_n": HapticParams().haptic_gain_n_m_per_n if gain is None else gain}


def stored_probes(engine: Engine, participant_id: int) -> set[str]:
    with Session(engine) as session:
        return set(
            session.scalars(
                select(ProbeTrialRow.probe).where(ProbeTrialRow.participant_id == participant_id)
            )
        )


def store_trials(engine: Engine, participant_id: int, trials: list[ProbeTrial]) -> None:
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        for t in trials:
            session.add(
                ProbeTrialRow(
                    participant_id=participant_id,
                    probe=t.probe,
                    trial_index=t.trial_index,
                    stimulus=t.stimulus,
                    response=t.response,
                    correct=t.correct,
                    context=dict(t.context),
                    driver=t.driver,
                )
            )
        session.commit()


def run_participant_probes(
    engine: Engine,
    code: str,
    responder: Responder | None = None,
    only: tuple[str, ...] = (),
    progress: Progress = no_progress,
    model: Any = None,
    observer: SessionObserver | None = None,
) -> dict[str, int]:
    """Run the design's probes for participant `code` (those not yet stored; `only`: just
    these) and store them; returns probe -> trials stored. Without `responder`, the
    participant's simulated person answers (the same traits as in its task trials: drawn
    from `model`, a `ParticipantModel`, when the trials were). `observer` is told each
    probe trial as it is answered (a `probe` event: the participant's keys, the probe, the
    trial's index, stimulus, response and whether it was correct)."""
    # lazy: study.protocol.session costs 59 ms at start-up
    from study.protocol.session import participant_traits

    with Session(engine) as session:
        study, design = load_study(session)
        participant = find_participant(session, study, code)
        pid, group, seed, study_name = participant.id, participant.group, study.seed, study.name
        if participant.withdrawn_at is not None:
            raise StudyInputError(f"participant {code} withdrew; expected one still in the study")
    if not design.probes:
        raise StudyInputError("the study's design names no probes; expected a [probes] table")
    for name in only:
        if name not in design.probes:
            raise StudyInputError(
                f"probe {name!r} is not in the study's design; expected one of "
                f"{', '.join(design.probes)}"
            )
    rng = np.random.default_rng([seed, zlib.crc32(code.encode()), 0x9B0BE])
    if responder is None:
        responder = SimulatedResponder(participant_traits(seed, code, group, model), rng)
    observer = observer or SessionObserver()

    def told(t: ProbeTrial) -> None:
        observer.event(
            "probe",
            study=study_name,
            participant=code,
            group=group,
            driver=t.driver,
            probe=t.probe,
            trial_index=t.trial_index,
            stimulus=t.stimulus,
            response=t.response,
            correct=t.correct,
        )

    done = stored_probes(engine, pid)
    stored = {}
    for name, n in design.probes.items():
        if (only and name not in only) or name in done:
            continue
        trials = run_probe(
            name,
            n,
            responder,
            rng,
            probe_context(design),
            progress,
            told,
        )
        store_trials(engine, pid, trials)
        stored[name] = len(trials)
    return stored


def run_all_probes(engine: Engine, model: Any = None, progress: Progress = no_progress) -> int:
    """Every participant's probes answered by its simulated person; returns the trials
    stored."""
    with Session(engine) as session:
        codes = list(session.scalars(select(Participant.code).order_by(Participant.code)))
    stored = 0
    for k, code in enumerate(codes):
        progress(code, k, len(codes))
        stored += sum(run_participant_probes(engine, code, model=model).values())
    return stored


def probe_frame(engine: Engine) -> pd.DataFrame:
    """Every stored probe trial, one row each (`PROBE_COLUMNS`), by participant code."""
    with Session(engine) as session:
        rows = session.execute(
            select(Participant.code, Participant.group, ProbeTrialRow)
            .join(ProbeTrialRow, ProbeTrialRow.participant_id == Participant.id)
            .order_by(Participant.code, ProbeTrialRow.probe, ProbeTrialRow.trial_index)
        ).all()
        data = [
            (
                code,
                group,
                r.probe,
                r.trial_index,
                r.stimulus,
                r.response,
                r.correct,
                dict(r.context or {}),
                r.driver,
            )
            for code, group, r in rows
        ]
    return pd.DataFrame(data, columns=list(PROBE_COLUMNS))
