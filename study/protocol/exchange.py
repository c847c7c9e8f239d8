"""Import and export of trial summaries and NASA-TLX as tidy CSV (or Parquet).

The column contracts (other tools rely on them; keep them exactly):

- trials: participant, group, task, condition, trial, completion_time_s,
  peak_proximal_force_n, peak_distal_force_n, success
- tlx: participant, task, condition, mental, physical, temporal, performance, effort,
  frustration, and optionally w_mental ... w_frustration (tallies of the 15 choices,
  summing to 15)

An import is checked row by row before anything is written, and written in one
transaction: all or nothing. Errors name the file, the row (as a spreadsheet numbers
it: the header is row 1) and the column. Export writes the measured (non-practice),
completed trials, the latest attempt of each, and a codebook of every column.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.engine import write_transaction
from db.models.study import CODE_PATTERN, Participant
from db.models.tlx import TLX_SUBSCALES, TlxResponse
from db.models.trial import SAMPLE_COLUMNS, Sample, Trial
from study.analysis.frames import trial_frame
from study.errors import StudyInputError
from study.protocol.design import StudyDesign
from study.protocol.roster import load_study
from study.protocol.tlx import check_rating, check_weights

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
        frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise StudyInputError(f"{path} is not a readable CSV: {exc}") from None
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise StudyInputError(f"{path} lacks column {missing[0]!r}; expected {', '.join(required)}")
    extra = [c for c in frame.columns if c not in required + optional]
    if extra:
        raise StudyInputError(
            f"{path} has unknown column {extra[0]!r}; expected {', '.join(required + optional)}"
        )
    return frame


def _number(p: _Problems, row: int, col: str, text: str, minimum: float = 0.0) -> float | None:
    try:
        value = float(text)
    except ValueError:
        p.add(row, col, f"{text!r} is not a number")
        return None
    if not math.isfinite(value) or value < minimum:
        p.add(row, col, f"{text!r}; expected a finite value >= {minimum:g}")
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
        if not trial.isdigit() or int(trial) < 1:
            p.add(row, "trial", f"{trial!r}; expected a whole number >= 1")
        values = {c: _number(p, row, c, r[c]) for c in TRIAL_COLUMNS[5:8]}
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
                "trial": int(trial) if trial.isdigit() else 0,
                "success": success,
                **values,
            }
        )
    p.raise_if_any()
    return rows


def _check_tlx(frame: pd.DataFrame, source: str, codes: set[str]) -> list[dict[str, Any]]:
    p = _Problems(source, [])
    rows = []
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
        ratings = {}
        for s in TLX_SUBSCALES:
            try:
                ratings[s] = check_rating(s, float(r[s]) if r[s].strip() else None)
            except (StudyInputError, ValueError) as exc:
                p.add(
                    row,
                    s,
                    str(exc) if isinstance(exc, StudyInputError) else f"{r[s]!r} is not a number",
                )
        weights = dict.fromkeys(TLX_SUBSCALES)
        if weighted:
            try:
                weights = check_weights({s: float(r[f"w_{s}"]) for s in TLX_SUBSCALES})
            except (StudyInputError, ValueError) as exc:
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
            for p in session.scalars(select(Participant).where(Participant.study_id == study.id))
        }
        known = {code: p.group for code, p in existing.items()}
        trials = _check_trials(trials_frame, design, str(trials_csv), known)
        tlx = (
            _check_tlx(tlx_frame, str(tlx_csv), {t["code"] for t in trials} | set(existing))
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
                    block_index=design.conditions.index(t["condition"]),
                    trial_index=t["trial"] - 1,
                    practice=False,
                    attempt=1,
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
    engine: Engine, out_dir: Path, fmt: str = "csv", samples: bool = False
) -> list[Path]:
    """Write trials, tlx (and samples) with the contract's columns, plus the codebook."""
    if fmt not in ("csv", "parquet"):
        raise StudyInputError(f"format {fmt!r}; expected csv or parquet")
    out_dir.mkdir(parents=True, exist_ok=True)
    with Session(engine) as session:
        load_study(session)
        trials = trial_frame(engine)[list(TRIAL_COLUMNS)]
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
        tlx = pd.DataFrame(tlx_rows, columns=list(TLX_COLUMNS + TLX_WEIGHT_COLUMNS))
        frames = {"trials": trials, "tlx": tlx}
        if samples:
            query = (
                select(Participant.code, Trial.task, Trial.condition, Trial.trial_index, Sample)
                .join(Trial, Sample.trial_id == Trial.id)
                .join(Participant, Trial.participant_id == Participant.id)
                .where(Trial.status == "completed", Trial.practice.is_(False))
                .order_by(Trial.id, Sample.seq)
            )
            frames["samples"] = pd.DataFrame(
                [
                    {
                        "participant": c,
                        "task": task,
                        "condition": cond,
                        "trial": ti + 1,
                        "seq": s.seq,
                        **{k: getattr(s, k) for k in SAMPLE_COLUMNS},
                    }
                    for c, task, cond, ti, s in session.execute(query)
                ],
                columns=["participant", "task", "condition", "trial", "seq", *SAMPLE_COLUMNS],
            )
    written = []
    for name, frame in frames.items():
        path = out_dir / f"{name}.{fmt}"
        tmp = path.with_name(f".{path.name}.partial")
        if fmt == "csv":
            frame.to_csv(tmp, index=False)
        else:
            frame.to_parquet(tmp, index=False)
        tmp.replace(path)
        written.append(path)
    columns = sorted({c for f in frames.values() for c in f.columns}, key=list(CODEBOOK).index)
    codebook = pd.DataFrame(
        [{"column": c, "unit": CODEBOOK[c][0], "meaning": CODEBOOK[c][1]} for c in columns]
    )
    codebook.to_csv(out_dir / "codebook.csv", index=False)
    written.append(out_dir / "codebook.csv")
    return written
