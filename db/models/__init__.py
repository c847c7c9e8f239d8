"""The study database's tables, one module per role, re-exported here.

`db.models` is the only place the schema is declared; Alembic migrations in
`db/migrations/versions` must produce exactly this schema (a test compares them).
"""

from db.models.audit import AuditEntry
from db.models.calibration import Calibration
from db.models.lease import SessionLease
from db.models.lsl import LslChunk, LslStream
from db.models.probe import ProbeTrial
from db.models.study import Participant, ScheduleBlock, Study
from db.models.tlx import TLX_SUBSCALES, TlxResponse
from db.models.trial import (
    TRIAL_STATUSES,
    SampleChunk,
    SampleSchema,
    Trial,
    TrialMeasure,
)

__all__ = [
    "TLX_SUBSCALES",
    "TRIAL_STATUSES",
    "AuditEntry",
    "Calibration",
    "LslChunk",
    "LslStream",
    "Participant",
    "ProbeTrial",
    "SampleChunk",
    "SampleSchema",
    "ScheduleBlock",
    "SessionLease",
    "Study",
    "TlxResponse",
    "Trial",
    "TrialMeasure",
]
