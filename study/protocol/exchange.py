"""Import and export of trial summaries and NASA-TLX as tidy CSV (or Parquet).

The column contracts (other tools rely on them; keep them exactly):

- trials: participant, group, task, condition, trial, completion_time_s,
  peak_proximal_force_n, peak_distal_force_n, success
- tlx: participant, task, condition, mental, physical, temporal, performance, effort,
  frustration, and optionally w_mental ... w_frustration (tallies of the 15 choices,
  summing to 15)

An import is checked row by row before anything is written, and written in one
transaction: all or nothing. Errors name the file, the row (as a spreadsheet numbers
it: the header is row 1), the column, and what was expected.

Reconciliation with the database (issue 18): a trial is filed in the block of its task
and condition (the participant's scheduled block, or for a participant known only from
imports the block that task and condition would have under the design); a slot that
already holds a completed trial (the same file imported twice, a trial already run) is
refused with one line rather than stored twice, so importing a file again changes
nothing; so is a questionnaire for a block that has one. Imported codes may be anything
`CODE_PATTERN` allows; enrolment continues after the highest code of the design's prefix.

Plausibility: numbers are plain decimals (no `inf`, `nan`, `3_0`), a completion time
lies within the trial limit (`MAX_TRIAL_S`), a peak force within `MAX_FORCE_N` of the
task's device, a trial number within the design's trials per block.

Export writes the measured (non-practice), completed trials, the latest attempt of each,
and a codebook of every column. Files are safe to open in a spreadsheet and replaced
atomically, never through a symbolic link (`study.protocol.export_files`): formula-like
text is exported with a leading single quote, which an import removes again.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session, selectinload

from db.engine import write_transaction
from db.models.study import CODE_PATTERN, Participant
from db.models.tlx import TLX_SUBSCALES, TlxResponse
from db.models.trial import Trial
from study.analysis.frames import trial_frame
from study.errors import StudyInputError
from study.protocol.design import MAX_TRIAL_S, StudyDesign
from study.protocol.export_files import AtomicFile, escape_frame, refuse_symlink, unescape_cell
from study.protocol.roster import load_study, plan_blocks
from study.protocol.tlx import check_rating, check_weights

MAX_FORCE_N = {"lcca": 20.0, "notes": 25.0}
"""Largest peak force a task's devices can produce, N; beyond it a value is a typo or a
unit slip. LCCA: the guidewire drive (K_t 0.043 N m/A, wheel radius 10 mm) would need
4.7 A, above a 2804 gimbal motor's rating (assumption, see teleop_core.follower.params);
NOTES: the hand's force bound of the NOTES task, `teleop_core.notes.task.HAND_MAX_FORCE_N`."""
_DECIMAL = re.compile(r"^[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?$")
_TRIAL_NUMBER = re.compile(r"^[0-9]{1,6}$")
_TEXT_COLUMNS = {"participant", "group", "task", "condition"}

if TYPE_CHECKING:
    from study.protocol.sample_export import Progress, SampleSelection

TRIAL_COLUMNS = (
    "participant",
    "group",
    "task",
    "condition",
    "trial",
    "completion_time_s",
    "peak_proximal_force_n",
    "peak_distal_force_n",
    "success",
)
TLX_COLUMNS = ("participant", "task", "condition", *TLX_SUBSCALES)
TLX_WEIGHT_COLUMNS = tuple(f"w_{s}" for s in TLX_SUBSCALES)
CODEBOOK = {
    "participant": ("", "pseudonymous participant code, e.g. P007"),
    "group": ("", "experience group, by its name in the study design"),
    "task": ("", "lcca (guidewire into the left common carotid) or notes (endoscopy)"),
    "condition": ("", "VO (visual only) or HV (haptic-visual)"),
    "trial": ("", "measured trial number within the task x condition block, from 1"),
    "completion_time_s": ("s", "time from start to success (or to the time limit)"),
    "peak_proximal_force_n": ("N", "largest proximal insertion force (the drive's estimate)"),
    "peak_distal_force_n": ("N", "largest distal force on the phantom"),
    "success": ("", "true if the tip reached the target"),
    **{s: ("0-100", f"NASA-TLX {s} rating, steps of 5") for s in TLX_SUBSCALES},
    **{
        f"w_{s}": ("count", f"times {s} was chosen in the 15 pairwise comparisons")
        for s in TLX_SUBSCALES
    },
    "seq": ("", "sample number within the trial"),
    "t_s": ("s", "time since the trial started"),
    "insertion_m": ("m", "guidewire insertion length"),
    "rotation_rad": ("rad", "guidewire rotation"),
    "tip_x_m": ("m", "tip position, x"),
    "tip_y_m": ("m", "tip position, y"),
    "tip_z_m": ("m", "tip position, z"),
    "branch": ("", "vessel the tip is in (DAo, arch, AAo, LSA, LCCA, BCT)"),
    "proximal_force_n": ("N", "proximal force, reference (simulation or load cell)"),
    "proximal_force_est_n": ("N", "proximal force estimated from the motor current"),
    "distal_force_n": ("N", "distal force on the phantom"),
    "dial_angle_rad": ("rad", "haptic dial angle"),
    "dial_torque_n_m": ("N m", "torque the dial's motor rendered"),
}


@dataclass
class _Problems:
    source: str
    items: list[str]

    def add(self, row: int, column: str, message: str) -> None:
        self.items.append(f"{self.source} row {row}, column {column}: {message}")

    def raise_if_any(self) -> None:
        if self.items:
            more = f" (and {len(self.items) - 1} more)" if len(self.items) > 1 else ""
            raise StudyInputError(self.items[0] + more)


def _read(path: Path, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> pd.DataFrame:
    if not path.is_file():
        raise StudyInputError(f"{path} does not exist")
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, encoding="utf-8")
    except pd.errors.EmptyDataError:
        raise StudyInputError(f"{path} is empty; expected a header row and data rows") from None
    except UnicodeDecodeError as exc:
        raise StudyInputError(
            f"{path} is not UTF-8 text (byte {exc.object[exc.start]:#04x} at offset "
            f"{exc.start}); expected a UTF-8 CSV"
        ) from None
    except (pd.errors.ParserError, OSError) as exc:
        raise StudyInputError(f"{path} is not a readable CSV: {_first_line(exc)}") from None
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise StudyInputError(f"{path} lacks column {missing[0]!r}; expected {', '.join(required)}")
    extra = [c for c in frame.columns if c not in required + optional]
    if extra:
        raise StudyInputError(
            f"{path} has unknown column {extra[0]!r}; expected {', '.join(required + optional)}"
        )
    if frame.empty:
        raise StudyInputError(f"{path} has a header but no rows; expected at least one data row")
    for column in _TEXT_COLUMNS.intersection(frame.columns):
        frame[column] = frame[column].map(unescape_cell)  # an exported file imports back
    return frame


def _first_line(exc: BaseException) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def _number(
    p: _Problems, row: int, col: str, text: str, minimum: float = 0.0, maximum: float = math.inf
) -> float | None:
    """A plain decimal within [minimum, maximum], else a problem naming it."""
    expected = f"a number from {minimum:g} to {maximum:g}"
    if not _DECIMAL.match(text.strip()):
        p.add(row, col, f"{text!r} is not a plain decimal number; expected {expected}")
        return None
    value = float(text)
    if not (math.isfinite(value) and minimum <= value <= maximum):
        p.add(row, col, f"{text!r} is out of range; expected {expected}")
        return None
    return value


_BOOL = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}


def _check_trials(
    frame: pd.DataFrame, design: StudyDesign, source: str, known: dict[str, str]
) -> list[dict[str, Any]]:
    p = _Problems(source, [])
    rows, seen = [], {}
    for i, r in enumerate(frame.to_dict("records")):
        row = i + 2
        code = r["participant"].strip()
        if not CODE_PATTERN.match(code):
            p.add(row, "participant", f"{code!r} is not a pseudonymous code; expected e.g. P007")
        if r["group"] not in design.groups:
            p.add(row, "group", f"{r['group']!r}; expected one of {', '.join(design.groups)}")
        elif known.setdefault(code, r["group"]) != r["group"]:
            p.add(row, "group", f"{r['group']!r} but {code} is in group {known[code]!r}")
        if r["task"] not in design.tasks:
            p.add(row, "task", f"{r['task']!r}; expected one of {', '.join(design.tasks)}")
        if r["condition"] not in design.conditions:
            p.add(
                row,
                "condition",
                f"{r['condition']!r}; expected one of {', '.join(design.conditions)}",
            )
        trial = r["trial"].strip()
        n_max = design.trials_per_condition
        if not _TRIAL_NUMBER.match(trial) or not 1 <= int(trial) <= n_max:
            p.add(row, "trial", f"{trial!r}; expected a whole number from 1 to {n_max}")
            trial = "0"
        force_max = MAX_FORCE_N.get(r["task"], min(MAX_FORCE_N.values()))
        values = {
            "completion_time_s": _number(
                p, row, "completion_time_s", r["completion_time_s"], 0.0, MAX_TRIAL_S
            ),
            **{
                c: _number(p, row, c, r[c], 0.0, force_max)
                for c in ("peak_proximal_force_n", "peak_distal_force_n")
            },
        }
        success = _BOOL.get(r["success"].strip().lower())
        if success is None:
            p.add(row, "success", f"{r['success']!r}; expected true or false")
        key = (code, r["task"], r["condition"], trial)
        if key in seen:
            p.add(
                row,
                "trial",
                f"repeats row {seen[key]} ({code} {r['task']}/{r['condition']} trial {trial})",
            )
        seen[key] = row
        rows.append(
            {
                "code": code,
                "group": r["group"],
                "task": r["task"],
                "condition": r["condition"],
                "trial": int(trial),
                "success": success,
                "row": row,
                **values,
            }
        )
    p.raise_if_any()
    return rows


def _file_trials(
    session: Session,
    rows: list[dict[str, Any]],
    design: StudyDesign,
    existing: dict[str, Participant],
    source: str,
) -> None:
    """Set each row's block (index and id) and attempt; refuse slots already completed."""
    p = _Problems(source, [])
    ids = [x.id for x in existing.values()]
    taken: dict[tuple[int, int, int], list[tuple[int, str]]] = {}
    if ids:
        for pid, block_index, trial_index, attempt, status in session.execute(
            select(
                Trial.participant_id, Trial.block_index, Trial.trial_index, Trial.attempt,
                Trial.status,
            ).where(Trial.participant_id.in_(ids), Trial.practice.is_(False))
        ):  # fmt: skip
            taken.setdefault((pid, block_index, trial_index), []).append((attempt, status))
    for r in rows:
        participant = existing.get(r["code"])
        if participant is not None and participant.blocks:
            blocks = [
                (b.block_index, b.id, b.task, b.condition, b.n_trials) for b in participant.blocks
            ]
        else:
            order = participant.condition_order if participant is not None else design.conditions
            blocks = [
                (b["block_index"], None, b["task"], b["condition"], b["n_trials"])
                for b in plan_blocks(design, tuple(order))
            ]
        match = [b for b in blocks if b[2:4] == (r["task"], r["condition"])]
        slot = f"{r['code']} {r['task']}/{r['condition']} trial {r['trial']}"
        if not match:
            p.add(r["row"], "task", f"{slot}: no such block in its schedule")
            continue
        r["block_index"], r["block_id"], *_, n_trials = match[0]
        if r["trial"] > n_trials:
            p.add(r["row"], "trial", f"{slot}; expected 1 to {n_trials} in its scheduled block")
            continue
        before = (
            taken.get((participant.id, r["block_index"], r["trial"] - 1), [])
            if participant is not None
            else []
        )
        if any(status == "completed" for _, status in before):
            p.add(
                r["row"],
                "trial",
                f"{slot} is already stored; expected trials not yet in the database "
                "(was this file imported before?)",
            )
        r["attempt"] = max((a for a, _ in before), default=0) + 1
    p.raise_if_any()


def _check_tlx(
    frame: pd.DataFrame,
    source: str,
    codes: set[str],
    design: StudyDesign,
    stored: set[tuple[str, str, str]],
) -> list[dict[str, Any]]:
    p = _Problems(source, [])
    rows = []
    seen: dict[tuple[str, str, str], int] = {}
    weighted = all(c in frame.columns for c in TLX_WEIGHT_COLUMNS)
    if any(c in frame.columns for c in TLX_WEIGHT_COLUMNS) and not weighted:
        raise StudyInputError(
            f"{source} has some weight columns but not all; expected all of "
            f"{', '.join(TLX_WEIGHT_COLUMNS)} or none"
        )
    for i, r in enumerate(frame.to_dict("records")):
        row = i + 2
        if r["participant"] not in codes:
            p.add(
                row,
                "participant",
                f"{r['participant']!r} has no trials; expected a known participant",
            )
        if r["task"] not in design.tasks:
            p.add(row, "task", f"{r['task']!r}; expected one of {', '.join(design.tasks)}")
        if r["condition"] not in design.conditions:
            p.add(
                row,
                "condition",
                f"{r['condition']!r}; expected one of {', '.join(design.conditions)}",
            )
        key = (r["participant"], r["task"], r["condition"])
        if key in stored:
            p.add(
                row,
                "participant",
                f"{'/'.join(key)} already has a questionnaire; expected one per block "
                "(edit it with `study tlx edit`)",
            )
        elif key in seen:
            p.add(row, "participant", f"{'/'.join(key)} repeats row {seen[key]}")
        seen.setdefault(key, row)
        ratings = {}
        for s in TLX_SUBSCALES:
            text = r[s].strip()
            if not _DECIMAL.match(text):
                p.add(row, s, f"{r[s]!r} is not a plain decimal; expected 0-100 in steps of 5")
                continue
            try:
                ratings[s] = check_rating(s, float(text))
            except StudyInputError as exc:
                p.add(row, s, str(exc))
        weights = dict.fromkeys(TLX_SUBSCALES)
        if weighted:
            texts = {s: r[f"w_{s}"].strip() for s in TLX_SUBSCALES}
            bad = [s for s in TLX_SUBSCALES if not _DECIMAL.match(texts[s])]
            if bad:
                p.add(
                    row,
                    f"w_{bad[0]}",
                    f"{texts[bad[0]]!r} is not a plain decimal number; expected 0-5 choices",
                )
            else:
                try:
                    weights = check_weights({s: float(texts[s]) for s in TLX_SUBSCALES})
                except StudyInputError as exc:
                    p.add(row, "w_*", str(exc))
        rows.append(
            {
                "code": r["participant"],
                "task": r["task"],
                "condition": r["condition"],
                **ratings,
                **{f"w_{s}": weights[s] for s in TLX_SUBSCALES},
            }
        )
    p.raise_if_any()
    return rows


def import_data(engine: Engine, trials_csv: Path, tlx_csv: Path | None = None) -> tuple[int, int]:
    """Check both files completely, then write them in one transaction."""
    trials_frame = _read(trials_csv, TRIAL_COLUMNS)
    tlx_frame = _read(tlx_csv, TLX_COLUMNS, TLX_WEIGHT_COLUMNS) if tlx_csv else None
    with write_transaction(engine) as conn, Session(bind=conn) as session:
        study, design = load_study(session)
        existing = {
            p.code: p
            for p in session.scalars(
                select(Participant)
                .where(Participant.study_id == study.id)
                .options(selectinload(Participant.blocks))
            )
        }
        known = {code: p.group for code, p in existing.items()}
        trials = _check_trials(trials_frame, design, str(trials_csv), known)
        _file_trials(session, trials, design, existing, str(trials_csv))
        stored_tlx = {
            (code, task, condition)
            for code, task, condition in session.execute(
                select(Participant.code, TlxResponse.task, TlxResponse.condition)
                .join(Participant)
                .where(Participant.study_id == study.id)
            )
        }
        tlx = (
            _check_tlx(
                tlx_frame,
                str(tlx_csv),
                {t["code"] for t in trials} | set(existing),
                design,
                stored_tlx,
            )
            if tlx_frame is not None
            else []
        )
        for t in trials:
            participant = existing.get(t["code"])
            if participant is None:
                participant = Participant(
                    study_id=study.id,
                    code=t["code"],
                    group=t["group"],
                    condition_order=list(design.conditions),
                    site="imported",
                )
                session.add(participant)
                session.flush()
                existing[t["code"]] = participant
            session.add(
                Trial(
                    participant_id=participant.id,
                    task=t["task"],
                    condition=t["condition"],
                    block_id=t["block_id"],
                    block_index=t["block_index"],
                    trial_index=t["trial"] - 1,
                    practice=False,
                    attempt=t["attempt"],
                    driver="imported",
                    status="completed",
                    completion_time_s=t["completion_time_s"],
                    peak_proximal_force_n=t["peak_proximal_force_n"],
                    peak_distal_force_n=t["peak_distal_force_n"],
                    success=t["success"],
                )
            )
        for r in tlx:
            session.add(TlxResponse(participant_id=existing[r.pop("code")].id, **r))
        session.flush()
        session.commit()
    return len(trials), len(tlx)


def export_data(
    engine: Engine,
    out_dir: Path,
    fmt: str = "csv",
    samples: bool = False,
    selection: SampleSelection | None = None,
    *,
    per_trial: bool = False,
    progress: Progress | None = None,
) -> list[Path]:
    """Write trials, tlx (and samples) with the contract's columns, plus the codebook.

    Samples stream in bounded memory (`study.protocol.sample_export`); `selection`
    restricts them, `per_trial` writes one file per trial under `samples/` and skips
    the files an earlier run left complete. Every file is written under a temporary
    name and renamed only once all of them are complete.
    """
    from study.protocol.sample_export import (
        SAMPLE_EXPORT_COLUMNS,
        SampleSelection,
        select_trials,
        write_samples,
        write_samples_per_trial,
    )

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
        tlx_rows = [
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
    trials = trial_frame(engine)[list(TRIAL_COLUMNS)]
    tlx = pd.DataFrame(tlx_rows, columns=list(TLX_COLUMNS + TLX_WEIGHT_COLUMNS))
    frames = {"trials": trials, "tlx": tlx}
    columns = [c for f in frames.values() for c in f.columns]
    if samples:
        columns += SAMPLE_EXPORT_COLUMNS
    codebook = pd.DataFrame(
        [
            {"column": c, "unit": CODEBOOK[c][0], "meaning": CODEBOOK[c][1]}
            for c in sorted(set(columns), key=list(CODEBOOK).index)
        ]
    )
    out_dir.mkdir(parents=True, exist_ok=True)
    # every target checked before anything is written: a link refuses the whole export
    names = [f"{name}.{fmt}" for name in frames] + ["codebook.csv"]
    if samples and not per_trial:
        names.append(f"samples.{fmt}")
    for name in names:
        refuse_symlink(out_dir / name)
    staged: list[AtomicFile] = []

    def stage(name: str) -> AtomicFile:
        staged.append(AtomicFile(out_dir / name))
        return staged[-1]

    try:
        for name, frame in frames.items():
            out = stage(f"{name}.{fmt}")
            if fmt == "csv":
                escape_frame(frame).to_csv(out.file, index=False, encoding="utf-8")
            else:
                frame.to_parquet(out.file, index=False)
        escape_frame(codebook).to_csv(stage("codebook.csv").file, index=False, encoding="utf-8")
        sample_paths: list[Path] = []
        if samples and per_trial:
            result = write_samples_per_trial(
                engine, export_trials, out_dir / "samples", fmt, selection, progress=progress
            )
            sample_paths = result.written + result.skipped
        elif samples:
            path = out_dir / f"samples.{fmt}"
            write_samples(engine, export_trials, path, fmt, selection, progress=progress)
            sample_paths = [path]
        for out in staged:
            out.commit()
    except BaseException:
        for out in staged:
            out.abort()
        raise
    written = [out.path for out in staged]
    return written[:2] + sample_paths + written[2:]
