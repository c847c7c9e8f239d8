"""Import and export of trial summaries and NASA-TLX as tidy CSV (or Parquet).

The column contracts (other tools rely on them; keep them exactly):

- trials: participant, group, task, condition, trial, completion_time_s, the measures
  the study's tasks analyse, under their own names (`study.protocol.tasks`; LCCA:
  peak_proximal_force_n, peak_distal_force_n; NOTES: peak_force_demanded_n,
  peak_tip_force_n), success. A row fills its own task's measures and leaves the
  others empty; an import needs every analysed measure of a row's task and may add its
  other measures (LCCA's wall_contacts, NOTES's peak_force_rendered_n, ...).
- tlx: participant, task, condition, mental, physical, temporal, performance, effort,
  frustration, and optionally w_mental ... w_frustration (tallies of the 15 choices,
  summing to 15; all empty for a questionnaire without them)
- both files as `study export` writes them also carry `PROVENANCE_COLUMNS` (trials) and
  `TLX_PROVENANCE_COLUMNS` (tlx), optional on import

An import is checked row by row before anything is written, and written in one
transaction: all or nothing. Errors name the file, the row (as a spreadsheet numbers
it: the header is row 1), the column, and what was expected.

Reconciliation with the database: a trial is filed in the block of its task
and condition (the participant's scheduled block, or for a participant known only from
imports the block that task and condition would have under the design); a slot that
already holds a completed trial (the same file imported twice, a trial already run) is
refused with one line rather than stored twice, so importing a file again changes
nothing; so is a questionnaire for a block that has one. Imported codes may be anything
`CODE_PATTERN` allows; enrolment continues after the highest code of the design's prefix.

Plausibility: numbers are plain decimals (no `inf`, `nan`, `3_0`), a completion time
lies within the trial limit (`MAX_TRIAL_S`), a measure within its task's bound
(`Measure.max_value`: a peak force within what the task's device can produce), a trial
number within the design's trials per block.

Export writes the measured (non-practice), completed trials, the latest attempt of each,
and a codebook of every column. Files are safe to open in a spreadsheet and replaced
atomically, never through a symbolic link (`study.protocol.export_files`): formula-like
text is exported with a leading single quote, which an import removes again.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session, selectinload

from db.engine import write_transaction
from db.models.audit import AuditEntry
from db.models.study import CODE_PATTERN, Participant, ScheduleBlock
from db.models.tlx import TLX_SUBSCALES, TlxResponse
from db.models.trial import Trial, TrialMeasure
from study.errors import StudyInputError
from study.protocol.actor import current_actor
from study.protocol.csv_input import BOOL, DECIMAL, Problems, number, read_csv
from study.protocol.design import MAX_TRIAL_S, StudyDesign
from study.protocol.roster import load_study, plan_blocks
from study.protocol.tasks import COMPLETION_TIME, get_task, is_task
from study.protocol.tlx import check_rating, check_weights
from study.protocol.trial_table import measure_columns

_TRIAL_NUMBER = re.compile(r"^[0-9]{1,6}$")

TRIAL_KEYS = ("participant", "group", "task", "condition", "trial", "completion_time_s")
TRIAL_COLUMNS = (*TRIAL_KEYS, "peak_proximal_force_n", "peak_distal_force_n", "success")
"""The columns of an LCCA study's trials; another task's measures replace or join the
two peaks under their own names (`trial_columns`)."""
TLX_COLUMNS = ("participant", "task", "condition", *TLX_SUBSCALES)
TLX_WEIGHT_COLUMNS = tuple(f"w_{s}" for s in TLX_SUBSCALES)
_TEXT_COLUMNS = ("participant", "group", "task", "condition")
PROVENANCE_COLUMNS = (
    "block",
    "data_source",
    "driver",
    "withdrawn",
    "valid",
    "invalid_reason",
    "included",
)
"""What an export adds to each trial row so that the analysis can be redone from the
file alone: the block's place in the participant's order (from 1), whether the trial was
simulated or measured, who drove it, whether the participant withdrew, whether the trial
was marked invalid (and why), and whether the analysis includes it (`yes`, or why not).
An import takes the block order, the simulated label and the invalid marks back; a file
without these columns (an export from before them) imports with the design's order,
as measured (`imported`) and valid."""
TLX_PROVENANCE_COLUMNS = ("block", "data_source", "withdrawn", "included")


def _check_trials(
    frame: pd.DataFrame, design: StudyDesign, source: str, known: dict[str, str]
) -> list[dict[str, Any]]:
    p = Problems(source, [])
    rows: list[dict[str, Any]] = []
    seen: dict[tuple[Any, ...], int] = {}
    for i, r in enumerate(frame.to_dict("records")):
        row = i + 2
        code = r["participant"].strip()
        if not CODE_PATTERN.match(code):
            p.add(row, "participant", f"{code!r} is not a pseudonymous code; expected e.g. P007")
        if p.one_of(row, r, "group", design.groups) and (
            known.setdefault(code, r["group"]) != r["group"]
        ):
            p.add(row, "group", f"{r['group']!r} but {code} is in group {known[code]!r}")
        p.one_of(row, r, "task", design.tasks)
        p.one_of(row, r, "condition", design.conditions)
        trial = r["trial"].strip()
        n_max = design.trials_per_condition
        if not _TRIAL_NUMBER.match(trial) or not 1 <= int(trial) <= n_max:
            p.add(row, "trial", f"{trial!r}; expected a whole number from 1 to {n_max}")
            trial = "0"
        values = {
            COMPLETION_TIME: number(p, row, COMPLETION_TIME, r[COMPLETION_TIME], 0.0, MAX_TRIAL_S),
            **_measures(p, row, r, frame.columns),
        }
        success = BOOL.get(r["success"].strip().lower())
        if success is None:
            p.add(row, "success", f"{r['success']!r}; expected true or false")
        provenance = _provenance(p, row, r)
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
                **provenance,
                **values,
            }
        )
    p.raise_if_any()
    return rows


def _provenance(p: Problems, row: int, r: dict[str, str]) -> dict[str, Any]:
    """The row's `PROVENANCE_COLUMNS` an import keeps: its block (None without the
    column), its driver (`simulated` stays simulated, anything else is `imported`), its
    invalid mark, and whether its participant withdrew."""
    block: int | None = None
    text = r.get("block", "").strip()
    if text:
        if _TRIAL_NUMBER.match(text) and int(text) >= 1:
            block = int(text)
        else:
            p.add(row, "block", f"{text!r}; expected a whole number from 1")
    source = (r.get("driver", "") or r.get("data_source", "")).strip().lower()
    reason = r.get("invalid_reason", "").strip()
    valid = BOOL.get(r.get("valid", "true").strip().lower() or "true")
    if valid is None:
        p.add(row, "valid", f"{r['valid']!r}; expected true or false")
    if valid is False and not reason:
        reason = "marked invalid in the imported file"
    withdrawn = BOOL.get(r.get("withdrawn", "false").strip().lower() or "false")
    if withdrawn is None:
        p.add(row, "withdrawn", f"{r['withdrawn']!r}; expected true or false")
    return {
        "block": block,
        "driver": "simulated" if source == "simulated" else "imported",
        "invalid_reason": reason or None,
        "withdrawn": bool(withdrawn),
    }


def _measures(
    p: Problems, row: int, r: dict[str, str], columns: Iterable[str]
) -> dict[str, float | None]:
    """The row's task's measures: an analysed one must be given, another may be empty;
    a measure of another task must be empty."""
    if not is_task(r["task"]):
        return {}
    task = get_task(r["task"])
    own = {m.name for m in task.measures}
    out: dict[str, float | None] = {}
    for column in columns:
        if column in TRIAL_KEYS or column in PROVENANCE_COLUMNS or column in ("success", *own):
            continue
        if r[column].strip():
            p.add(
                row,
                column,
                f"{r[column]!r} for a {task.name} trial; expected it empty "
                f"(a measure of another task)",
            )
    for m in task.measures:
        text = r.get(m.name, "")
        if not text.strip():
            if m.analysed:
                where = "empty" if m.name in r else "missing"
                p.add(row, m.name, f"{where}; expected the {task.name} trial's {m.label}")
            continue
        high = m.max_value if m.max_value is not None else math.inf
        out[m.name] = number(p, row, m.name, text, 0.0, high)
    return out


def _file_trials(
    session: Session,
    rows: list[dict[str, Any]],
    design: StudyDesign,
    existing: dict[str, Participant],
    source: str,
) -> None:
    """Set each row's block (index and id) and attempt; refuse slots already completed."""
    p = Problems(source, [])
    ids = [x.id for x in existing.values()]
    taken: dict[tuple[int, int, int], list[tuple[int, str]]] = {}
    if ids:
        for pid, block_index, trial_index, attempt, status in session.execute(
            select(
                Trial.participant_id,
                Trial.block_index,
                Trial.trial_index,
                Trial.attempt,
                Trial.status,
            ).where(Trial.participant_id.in_(ids), Trial.practice.is_(False))
        ):
            taken.setdefault((pid, block_index, trial_index), []).append((attempt, status))
    for r in rows:
        participant = existing.get(r["code"])
        blocks: list[tuple[int, int | None, str, str, int]]
        if participant is not None and participant.blocks:
            blocks = [
                (b.block_index, b.id, b.task, b.condition, b.n_trials) for b in participant.blocks
            ]
        else:
            order = (
                participant.condition_order
                if participant is not None
                else _imported_order(rows, r["code"], design)
            )
            r["order"] = tuple(order)
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


def _imported_order(rows: list[dict[str, Any]], code: str, design: StudyDesign) -> list[str]:
    """The condition order of a participant first seen in the file: as its `block`
    column says (conditions by their first block), else the design's."""
    first: dict[str, int] = {}
    for r in rows:
        if r["code"] == code and r["block"] is not None:
            first[r["condition"]] = min(first.get(r["condition"], r["block"]), r["block"])
    if not first:
        return list(design.conditions)
    return sorted(design.conditions, key=lambda c: (first.get(c, 1 << 30), c))


def _check_tlx(
    frame: pd.DataFrame,
    source: str,
    codes: set[str],
    design: StudyDesign,
    stored: set[tuple[str, str, str]],
) -> list[dict[str, Any]]:
    p = Problems(source, [])
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
        p.one_of(row, r, "task", design.tasks)
        p.one_of(row, r, "condition", design.conditions)
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
            if not DECIMAL.match(text):
                p.add(row, s, f"{r[s]!r} is not a plain decimal; expected 0-100 in steps of 5")
                continue
            try:
                ratings[s] = check_rating(s, float(text))
            except StudyInputError as exc:
                p.add(row, s, str(exc))
        weights = _tlx_weights(p, row, r) if weighted else dict.fromkeys(TLX_SUBSCALES)
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


def _tlx_weights(p: Problems, row: int, r: dict[str, str]) -> Mapping[str, int | None]:
    """The row's tallies of the 15 choices; all empty: a questionnaire without them."""
    weights: Mapping[str, int | None] = dict.fromkeys(TLX_SUBSCALES)
    texts = {s: r[f"w_{s}"].strip() for s in TLX_SUBSCALES}
    if any(texts.values()):  # a questionnaire without the choices leaves them all empty
        bad = [s for s in TLX_SUBSCALES if not DECIMAL.match(texts[s])]
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
    return weights


def _code_number(code: str) -> tuple[str, int]:
    """A code's prefix and number: P001 and P0001 are both ('P', 1)."""
    head = code.rstrip("0123456789")
    return head, int(code[len(head) :] or 0)


def _check_codes(rows: list[dict[str, Any]], existing: Iterable[str], source: str) -> None:
    """Refuse a code that is another code with other leading zeros (P0001 beside P001):
    two spellings of one participant number would be two people in every analysis."""
    p = Problems(source, [])
    spelled: dict[tuple[str, int], str] = {_code_number(c): c for c in existing}
    for r in rows:
        key = _code_number(r["code"])
        other = spelled.setdefault(key, r["code"])
        if other != r["code"]:
            p.add(
                r["row"],
                "participant",
                f"{r['code']!r} beside {other!r}, the same number "
                f"written with other zeros; expected {other}",
            )
    p.raise_if_any()


def _check_enrolled(rows: list[dict[str, Any]], existing: Iterable[str], source: str) -> None:
    """Refuse a code the study has not enrolled (the import enrols only when asked)."""
    p = Problems(source, [])
    known = set(existing)
    for r in rows:
        if r["code"] not in known:
            p.add(
                r["row"],
                "participant",
                f"{r['code']!r} is not enrolled in this study; expected an enrolled code "
                "(give --enrol-new to enrol the participants the file is the first to name)",
            )
    p.raise_if_any()


def _file_hash(path: Path) -> str:

    digest = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def import_data(
    engine: Engine,
    trials_csv: Path,
    tlx_csv: Path | None = None,
    actor: str | None = None,
    *,
    enrol_new: bool = False,
) -> tuple[int, int]:
    """Check both files completely, then write them in one transaction, with an audit row
    per file (who, when, the file's name and SHA-256, its rows). A participant the study
    does not have is refused (a typo'd code would be a new person with a schedule) unless
    `enrol_new`: then one first seen here is enrolled with the design's schedule
    (conditions in the design's order), so `study run` runs the blocks and trials the
    file did not hold."""

    who = current_actor(actor)
    with Session(engine) as session:
        _, design = load_study(session)
    measures = tuple(m for m in measure_columns(design.tasks) if m != COMPLETION_TIME)
    trials_frame = read_csv(
        trials_csv, (*TRIAL_KEYS, "success"), (*measures, *PROVENANCE_COLUMNS), _TEXT_COLUMNS
    )
    tlx_frame = (
        read_csv(
            tlx_csv,
            TLX_COLUMNS,
            (*TLX_WEIGHT_COLUMNS, *TLX_PROVENANCE_COLUMNS),
            _TEXT_COLUMNS,
        )
        if tlx_csv
        else None
    )
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
        _check_codes(trials, existing, str(trials_csv))
        if not enrol_new:
            _check_enrolled(trials, existing, str(trials_csv))
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
            participant = _participant_of(session, t, existing, study.id, design, trials_csv, who)
            if t["block_id"] is None:  # a block planned above
                t["block_id"] = next(
                    b.id for b in participant.blocks if b.block_index == t["block_index"]
                )
            session.add(_imported_trial(t, participant.id))
        for r in tlx:
            session.add(TlxResponse(participant_id=existing[r.pop("code")].id, **r))
        for kind, path, n in (
            ("trials_csv", trials_csv, len(trials)),
            ("tlx_csv", tlx_csv, len(tlx)),
        ):
            if path is not None:
                session.add(_import_audit(kind, path, n, study.id, who))
        session.flush()
        session.commit()
    return len(trials), len(tlx)


def _participant_of(
    session: Session,
    t: dict[str, Any],
    existing: dict[str, Participant],
    study_id: int,
    design: StudyDesign,
    trials_csv: Path,
    who: str,
) -> Participant:
    """The participant of the checked trial row `t`: enrolled (with an audit row) when the
    file is the first to name them, given the design's schedule when they have none."""
    participant = existing.get(t["code"])
    if participant is None:
        participant = Participant(
            study_id=study_id,
            code=t["code"],
            group=t["group"],
            condition_order=list(t.get("order") or design.conditions),
            site="imported",
        )
        session.add(participant)
        session.flush()
        existing[t["code"]] = participant
        if t["withdrawn"]:
            from datetime import UTC, datetime

            participant.withdrawn_at = datetime.now(UTC)
            participant.withdrawal_reason = f"withdrawn in {trials_csv.name}"
        session.add(
            AuditEntry(
                entity="participant",
                entity_id=participant.id,
                field="enrolled",
                old_value=None,
                new_value=json.dumps(
                    {"group": participant.group, "site": participant.site, "by": "import"}
                ),
                reason=f"first seen in {trials_csv.name}",
                actor=who,
            )
        )
    if not participant.blocks:  # new here, or imported before it got a schedule
        order = tuple(participant.condition_order)
        participant.blocks = [ScheduleBlock(**b) for b in plan_blocks(design, order)]
        session.flush()
    return participant


def _imported_trial(t: dict[str, Any], participant_id: int) -> Trial:
    """The completed trial the checked row `t` describes, with its task's own measures."""
    trial = Trial(
        participant_id=participant_id,
        task=t["task"],
        condition=t["condition"],
        block_id=t["block_id"],
        block_index=t["block_index"],
        trial_index=t["trial"] - 1,
        practice=False,
        attempt=t["attempt"],
        driver=t["driver"],
        status="completed",
        invalid_reason=t["invalid_reason"],
        completion_time_s=t[COMPLETION_TIME],
        success=t["success"],
    )
    own = [m.name for m in get_task(t["task"]).measures]
    trial.measures = {name: TrialMeasure(name=name, value=t[name]) for name in own if name in t}
    return trial


def _import_audit(kind: str, path: Path, rows: int, study_id: int, who: str) -> AuditEntry:
    """The audit row of one imported file: its name, SHA-256 and rows."""
    record = {"file": str(path.resolve()), "sha256": _file_hash(path), "rows": rows}
    return AuditEntry(
        entity="import",
        entity_id=study_id,
        field=kind,
        old_value=None,
        new_value=json.dumps(record),
        reason=None,
        actor=who,
    )
