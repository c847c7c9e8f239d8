"""The paper's figures from the study database (`study figures`, `study demo`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd
from sqlalchemy import Engine, exists, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import SAMPLE_COLUMNS, Sample, Trial
from study.analysis.figures import fig12, force_traces, label_source, save, tlx_profile
from study.analysis.frames import participant_means, tlx_frame, trial_frame
from study.analysis.source import DataSource, restrict
from study.analysis.stats import compare_conditions
from study.errors import StudyInputError


def _samples(engine: Engine, trial_id: int) -> pd.DataFrame:
    with Session(engine) as session:
        rows = session.scalars(
            select(Sample).where(Sample.trial_id == trial_id).order_by(Sample.seq)
        ).all()
    return pd.DataFrame([{c: getattr(s, c) for c in SAMPLE_COLUMNS} for s in rows])


def _trace_trials(engine: Engine, driver: str | None = None) -> list[tuple[int, str]]:
    """The VO trial with the highest peak distal force, and the same participant's
    HV trial with the same number: a collision felt and not felt. Only trials with
    samples (imported ones have none)."""
    recorded = exists().where(Sample.trial_id == Trial.id)
    query = (
        select(Trial, Participant.code)
        .join(Participant)
        .where(Trial.status == "completed", Trial.practice.is_(False), Trial.condition == "VO")
        .where(recorded)
        .order_by(Trial.peak_distal_force_n.desc())
    )
    if driver is not None:
        query = query.where(Trial.driver == driver)
    with Session(engine) as session:
        vo = session.execute(query).first()
        if vo is None:
            return []
        trial, code = vo
        hv = session.scalars(
            select(Trial).where(
                Trial.participant_id == trial.participant_id, Trial.condition == "HV",
                Trial.trial_index == trial.trial_index, Trial.status == "completed",
                Trial.practice.is_(False), recorded,
            )
        ).first()  # fmt: skip
    out = [(trial.id, f"{code}, VO, trial {trial.trial_index + 1}")]
    if hv is not None:
        out.append((hv.id, f"{code}, HV, trial {hv.trial_index + 1}"))
    return out


def write_figures(
    engine: Engine, out_dir: Path, formats: Sequence[str] = ("pdf", "svg", "png"),
    width: str = "double", driver: str | None = None,
) -> list[Path]:  # fmt: skip
    """Every figure carries the data-source note when any drawn trial is simulated."""
    trials, tlx = trial_frame(engine), tlx_frame(engine)
    if not len(trials):
        raise StudyInputError("the database holds no completed trials to draw")
    trials, tlx = restrict(trials, tlx, driver)
    note = DataSource.of(trials).note
    out_dir.mkdir(parents=True, exist_ok=True)
    long = participant_means(trials, tlx)
    comparisons, _ = compare_conditions(long)
    fig = label_source(fig12(long, comparisons, width), note)
    paths = save(fig, out_dir, "fig12_groups", formats)
    for trial_id, title in _trace_trials(engine, driver):
        name = "fig9_forces_" + title.split(",")[1].strip().lower()
        fig = label_source(force_traces(_samples(engine, trial_id), title), note)
        paths += save(fig, out_dir, name, formats)
    if len(tlx):
        fig = label_source(tlx_profile(tlx, "single"), note)
        paths += save(fig, out_dir, "tlx_profile", formats)
    return paths
