"""Probe trials out and in as tidy CSV: `study export` writes `probe_trials.csv` (and
its codebook rows) when the study has probe trials; `study import --probes FILE` reads
one back, all rows or none.

Columns (a contract, as the trials file's): participant, probe, probe_trial (from 1),
stimulus, stimulus_unit, response, response_unit, correct (true/false or empty),
context (a JSON object of the settings the measurement model needs), driver (the
original driver; an import stores `imported`). Errors name the file, the row (the
header is row 1), the column and what was expected.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd
from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.probe import ProbeTrial as ProbeTrialRow
from db.models.study import Participant
from study.errors import StudyInputError
from study.probes import get_probe, is_probe, probe_names
from study.protocol.csv_input import BOOL, DECIMAL, Problems, read_csv

PROBE_FILE_COLUMNS = (
    "participant",
    "probe",
    "probe_trial",
    "stimulus",
    "stimulus_unit",
    "response",
    "response_unit",
    "correct",
    "context",
    "driver",
)
CODEBOOK = {
    "probe_trial": ("", "trial number within the participant's probe, from 1"),
    "stimulus": (
        "stimulus_unit",
        "the probe's stimulus in its unit (a force step, a foreperiod, a "
        "target angle, a torque ramp's rate)",
    ),
    "stimulus_unit": ("", "the stimulus's SI unit"),
    "response": (
        "response_unit",
        "the answer in its unit (the interval chosen, a time, an angle, "
        "a torque); empty when none was given",
    ),
    "response_unit": ("", "the response's SI unit"),
    "correct": ("", "forced-choice probes: true if the interval chosen held the stimulus"),
    "context": (
        "JSON",
        "settings the probe's measurement model needs (the dial's gain, "
        "N m/N; the interval holding the stimulus)",
    ),
    "driver": ("", "who answered: simulated, keyboard, hardware (or imported)"),
}


def codebook() -> dict[str, tuple[str, str]]:
    book = dict(CODEBOOK)
    book["probe"] = (
        "",
        "the probe: " + "; ".join(f"{p} (tells {get_probe(p).trait})" for p in probe_names()),
    )
    return book


def export_frame(trials: pd.DataFrame) -> pd.DataFrame:
    """`store.probe_frame` as the file's columns."""
    rows = []
    for r in trials.itertuples():
        probe = get_probe(r.probe)
        rows.append(
            {
                "participant": r.participant,
                "probe": r.probe,
                "probe_trial": int(r.trial_index) + 1,
                "stimulus": r.stimulus,
                "stimulus_unit": probe.stimulus_unit,
                "response": r.response,
                "response_unit": probe.response_unit,
                "correct": ""
                if r.correct is None or pd.isna(r.correct)
                else str(bool(r.correct)).lower(),
                "context": json.dumps(r.context, sort_keys=True),
                "driver": r.driver,
            }
        )
    return pd.DataFrame(rows, columns=list(PROBE_FILE_COLUMNS))


def read_probe_file(path: Path) -> list[dict]:
    """The rows of a probe trials file, checked cell by cell (not yet against the study)."""
    frame = read_csv(path, PROBE_FILE_COLUMNS, (), ("participant", "probe", "driver"))
    p = Problems(str(path), [])
    rows = []
    for i, r in enumerate(frame.to_dict("records"), start=2):
        if not is_probe(r["probe"]):
            p.add(i, "probe", f"{r['probe']!r}; expected one of {', '.join(probe_names())}")
            continue
        if not (r["probe_trial"].isdigit() and 1 <= int(r["probe_trial"]) <= 100000):
            p.add(i, "probe_trial", f"{r['probe_trial']!r}; expected a whole number from 1")
            continue
        values: dict[str, float | None] = {}
        for column in ("stimulus", "response"):
            cell = r[column]
            if cell == "":
                values[column] = None
            elif DECIMAL.match(cell) and math.isfinite(float(cell)):
                values[column] = float(cell)
            else:
                p.add(i, column, f"{cell!r}; expected a plain decimal number or empty")
        correct = r["correct"].lower()
        if correct not in ("", *BOOL):
            p.add(i, "correct", f"{r['correct']!r}; expected true, false or empty")
        try:
            context = json.loads(r["context"] or "{}")
        except json.JSONDecodeError:
            context = None
        if not isinstance(context, dict) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in context.values()
        ):
            p.add(i, "context", f"{r['context']!r}; expected a JSON object of numbers")
        if len(values) == 2 and correct in ("", *BOOL):
            rows.append(
                {
                    "row": i,
                    "code": r["participant"],
                    "probe": r["probe"],
                    "trial_index": int(r["probe_trial"]) - 1,
                    **values,
                    "correct": None if correct == "" else BOOL[correct],
                    "context": context,
                }
            )
    p.raise_if_any()
    return rows


def known_codes(engine: Engine, trials_csv: Path) -> set[str]:
    """The participants of the study and of a trials file about to be imported with the
    probes (an unreadable trials file adds none: its import says why)."""
    with Session(engine) as session:
        codes = set(session.scalars(select(Participant.code)))
    try:
        frame = pd.read_csv(trials_csv, dtype=str, keep_default_na=False, usecols=["participant"])
    except (OSError, ValueError, pd.errors.ParserError, UnicodeDecodeError):
        return codes
    return codes | set(frame["participant"])


def check_participants(rows: list[dict], known: set[str], path: Path) -> None:
    for r in rows:
        if r["code"] not in known:
            raise StudyInputError(
                f"{path} row {r['row']}, column participant: {r['code']!r}; expected a "
                "participant of the study or of the trials file"
            )


def check_not_stored(engine: Engine, rows: list[dict], path: Path) -> None:
    """Refuse, before anything is written, a probe trial the database already holds."""
    with Session(engine) as session:
        _duplicates(session, rows, path)


def _duplicates(session: Session, rows: list[dict], path: Path) -> dict[str, int]:
    ids = dict(session.execute(select(Participant.code, Participant.id)).all())
    stored = set(
        session.execute(
            select(Participant.code, ProbeTrialRow.probe, ProbeTrialRow.trial_index).join(
                Participant, Participant.id == ProbeTrialRow.participant_id
            )
        ).all()
    )
    seen = set()
    for r in rows:
        key = (r["code"], r["probe"], r["trial_index"])
        if key in stored or key in seen:
            raise StudyInputError(
                f"{path} row {r['row']}: {r['code']} {r['probe']} trial {r['trial_index'] + 1} "
                "is already stored or repeated; expected each probe trial once"
            )
        seen.add(key)
    return ids


def store_imported(session: Session, rows: list[dict], path: Path) -> int:
    """Add `rows` to `session` (the caller's transaction); refuses a trial already stored."""
    ids = _duplicates(session, rows, path)
    for r in rows:
        session.add(
            ProbeTrialRow(
                participant_id=ids[r["code"]],
                probe=r["probe"],
                trial_index=r["trial_index"],
                stimulus=r["stimulus"],
                response=r["response"],
                correct=r["correct"],
                context=r["context"],
                driver="imported",
            )
        )
    return len(rows)


def import_probes(engine: Engine, path: Path, rows: list[dict]) -> int:
    """Store the checked `rows` in one transaction."""
    # lazy: db.engine costs 5 ms at start-up
    from db.engine import write_transaction

    with write_transaction(engine) as conn, Session(bind=conn) as session:
        check_participants(rows, set(session.scalars(select(Participant.code))), path)
        n = store_imported(session, rows, path)
        session.commit()
    return n
