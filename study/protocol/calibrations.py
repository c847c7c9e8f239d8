"""Calibration results kept with the study: the `calibrations` table and a report file.

A calibration run from the terminal app is stored as one row, with the
recording's name and SHA-256 (so that a result can be traced to the exact file), the
held-out RMSE before and after and the whole report, and written beside it as a JSON
file (the same keys as `study calibrate`'s REPORT.json) that can be attached to a paper.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.calibration import Calibration
from db.models.study import Study
from teleop_core.files import write_atomically


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _rmse(value: object) -> float | None:
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else None


def store_calibration(
    engine: Engine, model: str, recording: Path, report: dict[str, Any], out_dir: Path
) -> tuple[int, Path]:
    """Store one calibration; returns its id and the report file written into `out_dir`."""
    report = json.loads(json.dumps(report, default=float))  # plain JSON, as REPORT.json
    sha256 = _sha256(recording)
    with Session(engine) as session, session.begin():
        study = session.scalars(select(Study)).first()
        row = Calibration(
            study_id=study.id if study is not None else None,
            model=model,
            recording_name=recording.name,
            recording_sha256=sha256,
            rmse_before=_rmse(report.get("rmse_before")),
            rmse_after=_rmse(report.get("rmse_after")),
            report=report,
        )
        session.add(row)
        session.flush()
        calibration_id = row.id
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"calibration-{calibration_id:04d}-{recording.stem}.json"
    record = {
        "id": calibration_id,
        "model": model,
        "recording": recording.name,
        "recording_sha256": sha256,
        **report,
    }
    write_atomically(path, json.dumps(record, indent=2) + "\n")
    return calibration_id, path


def list_calibrations(engine: Engine, limit: int = 50) -> list[dict[str, Any]]:
    """The stored calibrations, newest first."""
    with Session(engine) as session:
        rows = session.scalars(
            select(Calibration).order_by(Calibration.id.desc()).limit(limit)
        ).all()
        return [
            {
                "id": r.id,
                "at": r.created_at,
                "model": r.model,
                "recording": r.recording_name,
                "rmse_before": r.rmse_before,
                "rmse_after": r.rmse_after,
                "verdict": (r.report or {}).get("verdict", ""),
            }
            for r in rows
        ]
