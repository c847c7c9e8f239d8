"""The paper's figures from the study database (`study figures`, `study demo`).

One set per task (`--task`, all tasks by default): Fig. 12 (`fig12_groups_<task>`),
Fig. 9 (`fig9_forces_<task>`, when the task's trials have samples) and the NASA-TLX
profile (`tlx_profile_<task>`). A task's Fig. 12 takes its marks from that task's own
comparisons (`compare_conditions`, Holm within task x measure: the p values `study
analyze` reports); its NASA-TLX panel is the weighted score unless the raw one is asked
for (`tlx_score`). `draw_figures` draws them; `write_figures` checks every one
(`figcheck`) before writing any, and writes their captions to `captions.md` beside
them (`CAPTIONS`): a caption inside a single-column figure took a third of its height.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd
import pyarrow as pa
from sqlalchemy import Engine, exists, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.trial import SampleChunk, Trial, TrialMeasure
from db.sample_reader import SampleReader
from study.analysis.comparisons import compare_conditions
from study.analysis.figcheck import FigureCheckError, check_figure
from study.analysis.figures import (
    TLX_SCORES,
    fig12,
    fig12_caption,
    fig12_labels,
    label_source,
    save,
    tested,
)
from study.analysis.frames import participant_means, tlx_frame, trial_frame, without_withdrawn
from study.analysis.source import DataSource, restrict
from study.analysis.stream_figure import DrawnStream, trial_streams_figure
from study.analysis.task_figures import figure_view, trace_measure
from study.analysis.tlx_figure import NOTE as TLX_PROFILE_CAPTION
from study.analysis.tlx_figure import tlx_profile
from study.analysis.trace_figure import force_traces
from study.errors import StudyInputError
from study.protocol.tasks import get_task

CAPTIONS = "captions.md"
"""The file of the figures' captions, written beside them."""


def _samples(engine: Engine, trial_id: int, task: str, columns: Sequence[str]) -> pd.DataFrame:
    """The `columns` (the task's names) of one trial's samples, in `seq` order.

    Read in Arrow batches (`SampleReader`) keeping only the columns drawn. A trial of
    ten minutes at 1 kHz (600,000 samples) read as ORM objects raised the peak memory by
    more than a gigabyte; read this way, by a tenth of it (`study bench export`).
    """
    the_task = get_task(task)
    with SampleReader(engine) as reader:
        batches = list(reader.trial(trial_id))
    if not batches:
        return pd.DataFrame({c: pd.Series(dtype=float) for c in columns})
    table = the_task.sample_table(pa.Table.from_batches(batches))
    return table.select(list(columns)).to_pandas()


def _trace_trials(engine: Engine, task: str, driver: str | None = None) -> list[tuple[int, str]]:
    """The task's VO trial with the highest `trace_measure` (LCCA: peak distal force),
    and the same participant's HV trial with the same number: a collision felt and not
    felt. Only trials with samples (imported ones have none). Of equal values, the first
    participant's (by code) first trial: not the first stored, which depends on which
    session worker committed first."""
    recorded = exists().where(SampleChunk.trial_id == Trial.id)
    measured = (Trial.status == "completed", Trial.practice.is_(False), Trial.task == task)
    traced = trace_measure(get_task(task))
    pick = (
        select(TrialMeasure.value)
        .where(TrialMeasure.trial_id == Trial.id, TrialMeasure.name == traced)
        .scalar_subquery()
    )
    query = (
        select(Trial, Participant.code)
        .join(Participant)
        .where(*measured, Trial.condition == "VO", recorded)
        .order_by(pick.desc(), Participant.code, Trial.block_index, Trial.trial_index, Trial.id)
    )
    if driver is not None:
        query = query.where(Trial.driver == driver)
    with Session(engine) as session:
        vo = session.execute(query).first()
        if vo is None:
            return []
        trial, code = vo
        hv = session.scalars(
            select(Trial)
            .where(
                *measured,
                Trial.participant_id == trial.participant_id,
                Trial.condition == "HV",
                Trial.trial_index == trial.trial_index,
                recorded,
            )
            .order_by(Trial.attempt.desc())
        ).first()
    out = [(trial.id, f"{code}, VO, trial {trial.trial_index + 1}")]
    if hv is not None:
        out.append((hv.id, f"{code}, HV, trial {hv.trial_index + 1}"))
    return out


@dataclass
class DrawnFigure:
    name: str
    """File name without the extension."""
    figure: plt.Figure
    expected_marks: dict[str, float | None] | None = None
    """Fig. 12: measure/group -> the reported Holm p (None: no test); else None."""
    caption: str = ""
    """The caption, for `captions.md` (the figure holds none)."""

    def problems(self) -> list[str]:
        """The figure check's findings (`figcheck.check_figure`); [] when legible."""
        return check_figure(self.figure, self.expected_marks)


def _marks(long: pd.DataFrame, comparisons: pd.DataFrame, task: str) -> dict[str, float | None]:
    """The mark each measure x group of Fig. 12 must show, from the reported p_holm."""
    out: dict[str, float | None] = {}
    shown = {m for score in TLX_SCORES for m in fig12_labels(task, score)}
    measures = [m for m in shown if m in set(long["measure"])]
    for measure in sorted(measures):
        for group in dict.fromkeys(long["group"]):
            rows = comparisons[
                (comparisons["measure"] == measure) & (comparisons["group"] == group)
            ]
            row = rows.iloc[0] if len(rows) else None
            out[f"{measure}/{group}"] = float(row["p_holm"]) if tested(row) else None
    return out


def tlx_score_of(long: pd.DataFrame, tlx_score: str) -> str:
    """The NASA-TLX score Fig. 12 shows: `tlx_score`, or raw when no questionnaire of
    the task has the pairwise choices a weighted score needs."""
    if tlx_score not in TLX_SCORES:
        raise StudyInputError(
            f"NASA-TLX score {tlx_score!r}; expected one of {', '.join(TLX_SCORES)}"
        )
    weighted = long[long["measure"] == "tlx_weighted"]["value"]
    if tlx_score == "weighted" and not weighted.notna().any():
        return "raw"
    return tlx_score


def _with_streams(
    engine: Engine, trial_ids: list[int], panels: list[tuple[pd.DataFrame, str]]
) -> list[tuple[pd.DataFrame, str, list[DrawnStream]]]:
    """Fig. 9's trials with the recorded streams the design's `[lsl] plot` asks for
    (by name or type); [] when it asks for none or none was recorded."""
    # lazy: db.lsl_streams costs 3 ms at start-up
    from db.lsl_streams import read_stream, trial_streams

    # lazy: study.protocol.roster costs 23 ms at start-up
    from study.protocol.roster import load_study

    with Session(engine) as session:
        _, design = load_study(session)
    asked = set(design.lsl.plot)
    if not asked or not trial_ids:
        return []
    streams = [s for s in trial_streams(engine, trial_ids) if s.name in asked or s.type in asked]
    names = sorted({s.name for s in streams})
    if not names:
        return []
    out = []
    for trial_id, (samples, title) in zip(trial_ids, panels, strict=True):
        drawn = []
        for name in names:
            stored = next((s for s in streams if s.trial_id == trial_id and s.name == name), None)
            if stored is None:
                continue
            frame = read_stream(engine, stored.id).to_pandas()
            drawn.append(
                DrawnStream(
                    stored.name,
                    stored.type,
                    stored.channels,
                    frame,
                    stored.gaps,
                    stored.channel_format == "string",
                )
            )
        out.append((samples, title, drawn))
    return out if any(d for _, _, d in out) else []


def tasks_of(trials: pd.DataFrame, tlx: pd.DataFrame, task: str | None) -> list[str]:
    """The tasks to draw: `task` (checked against the stored ones) or all of them."""
    known = list(dict.fromkeys([*trials["task"], *tlx["task"]]))
    if task is None:
        return known
    if task not in known:
        raise StudyInputError(
            f"no data for task {task!r}; expected one of {', '.join(known) or 'none stored'}"
        )
    return [task]


def draw_figures(
    engine: Engine,
    width: str = "double",
    driver: str | None = None,
    task: str | None = None,
    tlx_score: str = TLX_SCORES[0],
) -> list[DrawnFigure]:
    """Every figure of every task (or of `task`), each with the data-source note of the
    trials it draws and its caption; Fig. 12's NASA-TLX panel shows `tlx_score`
    (weighted or raw; raw where no questionnaire has the pairwise choices)."""
    trials, tlx, _ = without_withdrawn(engine, trial_frame(engine), tlx_frame(engine))
    if not len(trials):
        raise StudyInputError("the database holds no completed trials to draw")
    trials, tlx = restrict(trials, tlx, driver)
    long = participant_means(trials, tlx)
    comparisons, _ = compare_conditions(long)  # Holm within task x measure, as analyze
    drawn = []
    for name in tasks_of(trials, tlx, task):
        t_trials, t_tlx = trials[trials["task"] == name], tlx[tlx["task"] == name]
        note = DataSource.of(t_trials).note
        t_long = long[long["task"] == name]
        t_comp = comparisons[comparisons["task"] == name] if len(comparisons) else comparisons
        labels = fig12_labels(name, tlx_score_of(t_long, tlx_score))
        shown = t_long[t_long["measure"].isin(list(labels))]
        marks = _marks(shown, t_comp, name)
        if marks:  # else none of Fig. 12's measures was recorded in this task
            fig = label_source(fig12(shown, t_comp, width, labels), note)
            caption = fig12_caption(shown, t_comp, width, labels)
            drawn.append(DrawnFigure(f"fig12_groups_{name}", fig, marks, _captioned(note, caption)))
        drawn_columns = ["t_s", *figure_view(get_task(name)).traced_names()]
        traced = _trace_trials(engine, name, driver)
        panels = [(_samples(engine, i, name, drawn_columns), title) for i, title in traced]
        if panels:
            fig = label_source(force_traces(panels, name, width), note)
            caption = _captioned(note, figure_view(get_task(name)).sign_note)
            drawn.append(DrawnFigure(f"fig9_forces_{name}", fig, caption=caption))
        with_streams = _with_streams(engine, [i for i, _ in traced], panels)
        if with_streams:
            fig = label_source(trial_streams_figure(name, with_streams, width), note)
            drawn.append(DrawnFigure(f"fig9_streams_{name}", fig))
        if len(t_tlx):
            fig = label_source(tlx_profile(t_tlx, width), note)
            caption = _captioned(note, TLX_PROFILE_CAPTION)
            drawn.append(DrawnFigure(f"tlx_profile_{name}", fig, caption=caption))
    return drawn


def _captioned(note: str, caption: str) -> str:
    """The caption, after the data-source note when there is one (simulated data)."""
    return f"{note}. {caption}" if note else caption


def captions_markdown(drawn: Sequence[DrawnFigure]) -> str:
    """`captions.md`: one section per figure, its file name and its caption."""
    parts = ["# Figure captions\n"]
    for d in drawn:
        parts.append(f"## {d.name}\n\n{d.caption or '(no caption)'}\n")
    return "\n".join(parts)


def write_figures(
    engine: Engine,
    out_dir: Path,
    formats: Sequence[str] = ("pdf", "svg", "png"),
    width: str = "double",
    driver: str | None = None,
    task: str | None = None,
    tlx_score: str = TLX_SCORES[0],
) -> list[Path]:
    """Draw, check and write every figure and `captions.md`; nothing is written when one
    fails the check."""
    drawn = draw_figures(engine, width, driver, task, tlx_score)
    problems = [f"{d.name}: {p}" for d in drawn for p in d.problems()]
    if problems:
        for d in drawn:
            plt.close(d.figure)
        raise FigureCheckError(
            f"{len(problems)} figure check failure(s), nothing written: " + "; ".join(problems)
        )
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for d in drawn:
        paths += save(d.figure, out_dir, d.name, formats)
    captions = out_dir / CAPTIONS
    captions.write_text(captions_markdown(drawn), encoding="utf-8")
    return [*paths, captions]


def write_figures_at(db_url: str, out_dir: Path, width: str = "double") -> list[Path]:
    """`write_figures` (every format) for the database at `db_url`, opened and closed
    here: what `study demo` hands a session worker, which draws one width while the
    command draws the other."""
    # lazy: db.migrate costs 10 ms at start-up
    from db.migrate import open_database

    engine = open_database(db_url, create=False)
    try:
        return write_figures(engine, out_dir, width=width)
    finally:
        engine.dispose()
