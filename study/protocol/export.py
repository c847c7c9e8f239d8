"""Export of a study: trials, NASA-TLX (and samples) with the contract's columns, and a
codebook of every column (`study export`).

The trials' columns (`trial_columns`) are the common ones and the measures of the
study's tasks under their own names; the samples' columns are the tasks' own sample
columns; the codebook says what each measure and each sample column holds for each
task (`study.protocol.tasks`). See
`study.protocol.exchange` for the contracts and their import.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.study import Participant
from db.models.tlx import TLX_SUBSCALES, TlxResponse
from study.errors import StudyInputError
from study.protocol.exchange import (
    PROVENANCE_COLUMNS,
    TLX_COLUMNS,
    TLX_PROVENANCE_COLUMNS,
    TLX_WEIGHT_COLUMNS,
    TRIAL_KEYS,
)
from study.protocol.export_files import AtomicFile, escape_frame, refuse_symlink
from study.protocol.roster import load_study
from study.protocol.stream_export import (
    STREAM_CODEBOOK,
    StreamExport,
    collect_streams,
    write_streams,
)
from study.protocol.study_rows import invalid_rows, withdrawn_rows
from study.protocol.tasks import COMPLETION_TIME, SampleColumn, get_task
from study.protocol.trial_table import driver_connection, measure_columns, trial_frame
from teleop_core.progress import Progress, no_progress

if TYPE_CHECKING:
    from study.protocol.sample_export import ExportTrial, SampleSelection

CODEBOOK = {
    "participant": ("", "pseudonymous participant code, e.g. P007"),
    "group": ("", "experience group, by its name in the study design"),
    "task": ("", "lcca (guidewire into the left common carotid) or notes (endoscopy)"),
    "condition": ("", "VO (visual only) or HV (haptic-visual)"),
    "trial": ("", "measured trial number within the task x condition block, from 1"),
    "completion_time_s": ("s", "time from start to success (or to the time limit)"),
    "success": (
        "",
        "true if the tip reached the target (on a physical phantom: as the participant's "
        "button or the experimenter said; the trial's summary names which)",
    ),
    **{s: ("0-100", f"NASA-TLX {s} rating, steps of 5") for s in TLX_SUBSCALES},
    **{
        f"w_{s}": ("count", f"times {s} was chosen in the 15 pairwise comparisons")
        for s in TLX_SUBSCALES
    },
    "block": ("", "the block's place in the participant's order of blocks, from 1"),
    "data_source": ("", "simulated or measured (a questionnaire: its participant's trials)"),
    "driver": ("", "who drove the trial: simulated, keyboard, hardware or imported"),
    "withdrawn": ("", "true if the participant withdrew (their data are not analysed)"),
    "valid": ("", "false if the trial was marked invalid (kept, not analysed)"),
    "invalid_reason": ("", "why the trial was marked invalid; empty while it is valid"),
    "included": ("", "yes if `study analyze` uses the row, otherwise why not"),
    "seq": ("", "sample number within the trial"),
}
"""The columns every study has; each task's measures and sample columns are described
by the task (`codebook`)."""


def trial_columns(tasks: Iterable[str]) -> tuple[str, ...]:
    """The trials file's columns for a study of `tasks`: keys, every task's analysed
    measures (each once, in the tasks' order), success. (The other measures, such as
    LCCA's wall contacts, stay in the database: the file keeps the contract's columns.)"""
    measures = [m for m in measure_columns(tasks, analysed_only=True) if m != COMPLETION_TIME]
    return (*TRIAL_KEYS, *measures, "success")


def codebook(tasks: Iterable[str]) -> dict[str, tuple[str, str]]:
    """Column -> (unit, meaning) for a study of `tasks`: the common columns, each task's
    measures, and each task's sample columns (under their own names, as exported)."""
    specs = [get_task(t) for t in tasks]
    measures: dict[str, tuple[str, str]] = {}
    for t in specs:
        for m in t.measures:
            measures.setdefault(m.name, (m.unit, f"{t.name}: {m.description}"))
    out: dict[str, tuple[str, str]] = {}
    for column, entry in CODEBOOK.items():  # the measures right after completion_time_s
        out[column] = entry
        if column == COMPLETION_TIME:
            out.update(measures)
    out["task"] = ("", "; ".join(f"{t.name} ({t.title})" for t in specs))
    samples: dict[str, list[tuple[str, SampleColumn]]] = {}
    for t in specs:
        for c in t.sample_columns:
            samples.setdefault(c.name, []).append((t.name, c))
    for column, uses in samples.items():
        units = {c.unit for _, c in uses}
        meaning = "; ".join(f"{name}: {c.description}" for name, c in uses)
        out.setdefault(column, ("/".join(sorted(units)), meaning))
    return out


def export_data(
    engine: Engine,
    out_dir: Path,
    fmt: str = "csv",
    samples: bool = False,
    selection: SampleSelection | None = None,
    *,
    per_trial: bool = False,
    workers: int | None = None,
    progress: Progress = no_progress,
) -> list[Path]:
    """Write trials, tlx (and samples) with the contract's columns, plus the codebook.

    Samples stream in bounded memory (`study.protocol.sample_export`); `selection`
    restricts them, `per_trial` writes one file per trial under `samples/` and skips
    the files an earlier run left complete; `workers` reader threads read them
    (default: one per CPU, at most 4). Every file is written under a temporary
    name and renamed only once all of them are complete.
    """
    # lazy: study.protocol.sample_export costs 11 ms at start-up
    from study.protocol.sample_export import SampleSelection, select_trials

    if fmt not in ("csv", "parquet"):
        raise StudyInputError(f"format {fmt!r}; expected csv or parquet")
    selection = selection or SampleSelection()
    if not samples and (selection.restricted or per_trial):
        raise StudyInputError(
            "a sample selection or --per-trial was given without --samples; expected --samples"
        )
    with Session(engine) as session:
        _, design = load_study(session)
        export_trials = select_trials(session, design, selection) if samples else []
        tlx_rows = _tlx_rows(session)
    frames = _frames(engine, design.tasks, tlx_rows)
    study_tasks = list(dict.fromkeys([*design.tasks, *frames["trials"]["task"]]))
    streams = collect_streams(engine, export_trials, selection) if samples else StreamExport()
    book_frame = _codebook_frame(frames, study_tasks, streams, samples)
    out_dir.mkdir(parents=True, exist_ok=True)
    # every target checked before anything is written: a link refuses the whole export
    names = [f"{name}.{fmt}" for name in frames] + ["codebook.csv"]
    if samples and not per_trial:
        names.append(f"samples.{fmt}")
    for name in names:
        refuse_symlink(out_dir / name)
    staged: list[AtomicFile] = []
    try:
        for name, frame in frames.items():
            staged.append(_write_frame(frame, out_dir / f"{name}.{fmt}", fmt))
        staged.append(_write_frame(book_frame, out_dir / "codebook.csv", "csv"))
        staged += write_streams(streams, out_dir / "streams", fmt)
        sample_paths = (
            _write_sample_files(
                engine,
                export_trials,
                out_dir,
                fmt,
                selection,
                per_trial=per_trial,
                progress=progress,
                workers=workers,
                tasks=design.tasks,
            )
            if samples
            else []
        )
        for out in staged:
            out.commit()
    except BaseException:
        for out in staged:
            out.abort()
        raise
    written = [out.path for out in staged]
    return written[:2] + sample_paths + written[2:]


def _tlx_rows(session: Session) -> list[dict[str, object]]:
    """Every stored questionnaire, by participant code, with the contract's columns."""
    return [
        {
            "participant": code,
            "task": r.task,
            "condition": r.condition,
            **{s: getattr(r, s) for s in TLX_SUBSCALES},
            **{f"w_{s}": getattr(r, f"w_{s}") for s in TLX_SUBSCALES},
        }
        for r, code in session.execute(
            select(TlxResponse, Participant.code).join(Participant).order_by(Participant.code)
        )
    ]


def _frames(
    engine: Engine, tasks: tuple[str, ...], tlx_rows: list[dict[str, object]]
) -> dict[str, pd.DataFrame]:
    """The trials and TLX tables (and the probes' trials, if the study ran probes)."""
    # lazy: study.probes.exchange costs 3 ms at start-up
    from study.probes.exchange import export_frame

    # lazy: study.probes.store costs 8 ms at start-up
    from study.probes.store import probe_frame

    trials = trial_frame(engine, tasks)
    columns = list(trial_columns(dict.fromkeys([*tasks, *trials["task"]])))
    trials, tlx = _provenance(
        engine, trials, pd.DataFrame(tlx_rows, columns=list(TLX_COLUMNS + TLX_WEIGHT_COLUMNS))
    )
    trials = trials[columns + list(PROVENANCE_COLUMNS)]
    tlx = tlx[list(TLX_COLUMNS + TLX_WEIGHT_COLUMNS + TLX_PROVENANCE_COLUMNS)]
    frames = {"trials": trials, "tlx": tlx}
    probe_trials = probe_frame(engine)
    if len(probe_trials):  # a study that ran probes: their trials too
        frames["probe_trials"] = export_frame(probe_trials)
    return frames


def _provenance(
    engine: Engine, trials: pd.DataFrame, tlx: pd.DataFrame
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The trials and questionnaires with `PROVENANCE_COLUMNS` (and the questionnaires'
    `TLX_PROVENANCE_COLUMNS`): what the analysis needs besides the numbers."""

    with driver_connection(engine) as conn:
        withdrawn = withdrawn_rows(conn)
        invalid = invalid_rows(conn)
    trials = trials.copy()
    keys = zip(
        trials["participant"], trials["task"], trials["condition"], trials["trial"], strict=True
    )
    reasons = [invalid.get((c, t, k, int(n))) for c, t, k, n in keys]
    trials["data_source"] = [
        "simulated" if d == "simulated" else "measured" for d in trials["driver"]
    ]
    trials["withdrawn"] = trials["participant"].isin(list(withdrawn))
    trials["valid"] = [r is None for r in reasons]
    trials["invalid_reason"] = [r or "" for r in reasons]
    trials["included"] = [
        _included(withdrawn.get(c), w, r)
        for c, w, r in zip(trials["participant"], trials["withdrawn"], reasons, strict=True)
    ]
    tlx = tlx.copy()
    sources = trials.groupby("participant")["data_source"].agg(
        lambda s: s.iloc[0] if s.nunique() == 1 else "mixed"
    )
    blocks = trials.groupby(["participant", "task", "condition"])["block"].first()
    tlx_keys = list(zip(tlx["participant"], tlx["task"], tlx["condition"], strict=True))
    tlx["block"] = pd.array([blocks.get(k) for k in tlx_keys], dtype="Int64")
    tlx["data_source"] = [sources.get(c, "measured") for c in tlx["participant"]]
    tlx["withdrawn"] = tlx["participant"].isin(list(withdrawn))
    tlx["included"] = [
        _included(withdrawn.get(c), w, None)
        for c, w in zip(tlx["participant"], tlx["withdrawn"], strict=True)
    ]
    return trials, tlx


def _included(withdrawal: str | None, withdrawn: bool, invalid: str | None) -> str:
    if withdrawn:
        return f"no: participant withdrawn ({withdrawal})" if withdrawal else "no: withdrawn"
    if invalid is not None:
        return f"no: trial marked invalid ({invalid})"
    return "yes"


def _codebook_frame(
    frames: dict[str, pd.DataFrame], tasks: list[str], streams: StreamExport, samples: bool
) -> pd.DataFrame:
    """One row (column, unit, meaning) per column of the files written, in the
    codebook's order."""
    # lazy: study.probes.exchange costs 3 ms at start-up
    from study.probes.exchange import codebook as probe_codebook

    # lazy: study.protocol.sample_export costs 11 ms at start-up
    from study.protocol.sample_export import sample_export_columns

    columns = [c for f in frames.values() for c in f.columns]
    if samples:
        columns += sample_export_columns(tasks)
    book = codebook(tasks)
    book.update({c: e for c, e in probe_codebook().items() if c not in book})
    if streams.tables:  # every recorded instrument's channel, as `stream/channel`
        book.update({c: e for c, e in STREAM_CODEBOOK.items() if c not in book})
        book.update(streams.codebook)
        columns += [*STREAM_CODEBOOK, *streams.codebook]
    return pd.DataFrame(
        [
            {"column": c, "unit": book[c][0], "meaning": book[c][1]}
            for c in sorted(set(columns), key=list(book).index)
        ]
    )


def _write_frame(frame: pd.DataFrame, path: Path, fmt: str) -> AtomicFile:
    """`frame` staged at `path` (committed by the caller once every file is complete)."""
    out = AtomicFile(path)
    try:
        if fmt == "csv":
            escape_frame(frame).to_csv(out.file, index=False, encoding="utf-8")
        else:
            frame.to_parquet(out.file, index=False)
    except BaseException:
        out.abort()
        raise
    return out


def _write_sample_files(
    engine: Engine,
    export_trials: list[ExportTrial],
    out_dir: Path,
    fmt: str,
    selection: SampleSelection,
    *,
    per_trial: bool,
    progress: Progress,
    workers: int | None,
    tasks: tuple[str, ...],
) -> list[Path]:
    """The samples file (or, `per_trial`, the files under `samples/`, written and kept)."""
    # lazy: study.protocol.sample_export costs 11 ms at start-up
    from study.protocol.sample_export import write_samples, write_samples_per_trial

    if per_trial:
        result = write_samples_per_trial(
            engine,
            export_trials,
            out_dir / "samples",
            fmt,
            selection,
            progress=progress,
            workers=workers,
        )
        return result.written + result.skipped
    path = out_dir / f"samples.{fmt}"
    write_samples(
        engine,
        export_trials,
        path,
        fmt,
        selection,
        progress=progress,
        workers=workers,
        tasks=tasks,
    )
    return [path]
