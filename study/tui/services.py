"""What the terminal app asks of the study: the roster, what is next, questionnaires, analysis.

The app's widgets never touch the database themselves: they call these functions from
worker threads, and these call the service functions of `study.protocol` and
`study.analysis` (which own the queries). `StudyServices` bundles the engine with the
dependencies `make_app` is given (the estimator loader, the calibration function), so
tests hand the app their own. Heavy imports (pandas, pingouin, torch) happen on first
use inside a worker, which keeps the overview's start fast.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import Engine, select
from sqlalchemy.orm import Session

from db.models.audit import AuditEntry
from db.models.study import Participant
from db.models.trial import Trial
from study.errors import StudyInputError
from study.protocol.orphans import gone_sessions
from study.protocol.roster import add_participant, load_study, schedule
from teleop_core.progress import Progress, no_progress

if TYPE_CHECKING:
    from study.protocol.observer import LastingObserver
    from teleop_core.estimation.estimator import ForceEstimator

CalibrateFn = Callable[[Path, str, Progress], dict[str, Any]]
"""calibrate(recording, model, progress) -> the report (`study calibrate`'s REPORT.json keys)."""


@dataclass(frozen=True)
class NextTrial:
    """The next scheduled trial of one participant."""

    code: str
    block_index: int
    task: str
    condition: str
    practice: bool
    number: int
    """1-based among the block's practice trials or among its measured trials."""
    remaining: int
    """Trials the participant still has to do, this one included."""

    def describe(self) -> str:
        kind = "practice" if self.practice else "trial"
        return f"{self.task}/{self.condition} {kind} {self.number}"


@dataclass(frozen=True)
class Roster:
    """The study's plan and progress, as the overview and the participants list show it."""

    study: str
    seed: int
    practice_trials: int
    groups: dict[str, dict[str, int]]
    """group -> {"target": n, "enrolled": n}."""
    participants: list[dict[str, Any]]
    """`study.protocol.roster.schedule` rows (code, group, condition_order, blocks, ...)."""
    answered: set[tuple[str, str, str]] = field(default_factory=set)
    """(code, task, condition) of the blocks with a stored NASA-TLX."""
    break_s: float = 120.0
    """The design's planned rest after each block."""
    tlx_first: bool = True
    """The design's `tlx_before_next_block`: a finished block's questionnaire is due
    before the next block starts."""

    def withdrawn(self, code: str) -> str | None:
        """The withdrawal reason of `code`, or None while they are in the study."""
        row = next((r for r in self.participants if r["code"] == code), None)
        return row.get("withdrawn") if row is not None else None

    def next_trial(self, code: str) -> NextTrial | None:
        row = next((r for r in self.participants if r["code"] == code), None)
        if row is None or row.get("withdrawn"):
            return None
        remaining = row["trials_planned"] - row["trials_completed"]
        for b in row["blocks"]:
            if b["completed"] < b["planned"]:
                k = b["completed"]
                practice = k < self.practice_trials
                number = k + 1 if practice else k - self.practice_trials + 1
                return NextTrial(
                    code, b["block_index"], b["task"], b["condition"], practice, number, remaining
                )
        return None

    def tlx_due(self) -> list[tuple[str, str, str]]:
        """Finished blocks still without their questionnaire, in schedule order."""
        return [
            (r["code"], b["task"], b["condition"])
            for r in self.participants
            if not r.get("withdrawn")
            for b in r["blocks"]
            if b["completed"] >= b["planned"]
            and (r["code"], b["task"], b["condition"]) not in self.answered
        ]

    def sessions_done(self) -> int:
        return sum(
            1
            for r in self.participants
            if r["trials_planned"] and r["trials_completed"] >= r["trials_planned"]
        )

    def what_next(self) -> list[str]:
        """A few lines: questionnaires due, the next sessions, groups still to fill."""
        lines = [f"NASA-TLX due: {c} {t}/{k}" for c, t, k in self.tlx_due()[:3]]
        for r in self.participants:
            nxt = self.next_trial(r["code"])
            if nxt is not None:
                lines.append(f"next trial: {r['code']} {nxt.describe()}")
            if len(lines) >= 4:
                break
        for group, fill in self.groups.items():
            if fill["enrolled"] < fill["target"]:
                lines.append(f"enrol: {fill['target'] - fill['enrolled']} more {group}")
        return lines or ["the study is complete: run the analysis"]


@dataclass(frozen=True)
class StudyServices:
    """The app's dependencies: the database and what it cannot build itself."""

    engine: Engine
    load_estimator: Callable[[], ForceEstimator]
    """Called once, in a worker, before the first trial (loading it imports torch)."""
    calibrate: CalibrateFn | None = None
    """The calibration loop; None leaves the calibration screen waiting."""
    lsl_publish: bool = False
    """Publish the trials' markers and samples as LSL streams even when the design's
    `[lsl]` table does not say so (`study tui --lsl`)."""
    _lsl: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)
    """The app's LSL observer and where its notices go, once made (`lsl_observer`)."""

    def lsl_observer(self, notice: Callable[[str], None] | None = None) -> LastingObserver | None:
        """The design's `[lsl]` streams (and `lsl_publish`'s) for everything the app runs:
        one observer for the app's life (each trial is a session of its own; the streams
        stay open across them), made on the first call, ended by `close_lsl`. None when
        the design names no streams and publishing is off (pylsl is then never loaded).
        `notice`, when given, is told from then on of a stream lost (from a worker)."""
        if notice is not None:
            self._lsl["notice"] = notice
        if "observer" not in self._lsl:
            from study.lsl.observers import lasting_observers

            with Session(self.engine) as session:
                design = load_study(session)[1]
            self._lsl["observer"] = lasting_observers(
                self.engine,
                design,
                self.lsl_publish,
                lambda line: self._lsl.get("notice", lambda _: None)(line),
            )
        return self._lsl["observer"]

    def close_lsl(self) -> None:
        """End the LSL streams of `lsl_observer`, if it made any (the app quits)."""
        observer = self._lsl.pop("observer", None)
        if observer is not None:
            observer.close()

    def roster(self) -> Roster:
        # lazy: study.protocol.tlx costs 10 ms at start-up
        from study.protocol.tlx import answered_blocks

        with Session(self.engine) as session:
            study, design = load_study(session)
        plan = schedule(self.engine)
        return Roster(
            study=plan["study"],
            seed=study.seed,
            practice_trials=design.practice_trials,
            groups=plan["groups"],
            participants=plan["participants"],
            answered=answered_blocks(self.engine),
            break_s=design.break_s,
            tlx_first=design.tlx_before_next_block,
        )

    def record_checklist(self, code: str) -> None:
        """The session checklist (consent confirmed, device checked) as an audit row."""
        # lazy: study.protocol.withdrawal costs 4 ms at start-up
        from study.protocol.withdrawal import record_checklist

        record_checklist(self.engine, code)

    def checklist_recorded(self, code: str) -> bool:
        """Whether `code`'s session checklist is in the audit log (by this app or an
        earlier start of it), so that it is asked once per participant."""

        with Session(self.engine) as session:
            found = session.scalar(
                select(AuditEntry.id)
                .join(Participant, Participant.id == AuditEntry.entity_id)
                .where(
                    AuditEntry.entity == "participant",
                    AuditEntry.field == "session_checklist",
                    Participant.code == code,
                )
                .limit(1)
            )
        return found is not None

    def left_running(self) -> list[tuple[str, str]]:
        """(code, why) of each participant with a trial still `running` that belongs to
        no live session (the app or `study run` was killed, a machine lost): it counts
        as interrupted, and their next session marks it so and repeats it."""

        with Session(self.engine) as session:
            rows = session.execute(
                select(Participant.id, Participant.code)
                .join(Trial, Trial.participant_id == Participant.id)
                .where(Trial.status == "running")
                .distinct()
            ).all()
            codes = {pid: code for pid, code in rows}
            gone = gone_sessions(session, list(codes))
        return sorted((codes[pid], why.split("; ")[0]) for pid, why in gone.items())

    def withdraw(self, code: str, reason: str) -> None:
        # lazy: study.protocol.withdrawal costs 4 ms at start-up
        from study.protocol.withdrawal import withdraw

        withdraw(self.engine, code, reason)

    def note(self, code: str, text: str, session: bool = False) -> None:
        """Set `code`'s note, or (`session`) add a note on their session (audited)."""
        # lazy: study.protocol.withdrawal costs 4 ms at start-up
        from study.protocol.withdrawal import add_session_note, set_note

        (add_session_note if session else set_note)(self.engine, code, text)

    # the participant page (`study.tui.participant_page`): what is stored, corrections

    def participant_record(self, code: str) -> Any:
        """`study.protocol.participant_record.ParticipantRecord` of `code`."""
        # lazy: study.protocol.participant_record costs 5 ms at start-up
        from study.protocol.participant_record import participant_record

        return participant_record(self.engine, code)

    def mark_trial(self, trial_id: int, valid: bool, reason: str) -> str:
        """Mark a measured trial invalid or valid again (audited); its description."""
        # lazy: study.protocol.corrections costs 6 ms at start-up
        from study.protocol.corrections import mark_trial

        return mark_trial(self.engine, trial_id, valid, reason)

    def reinstate(self, code: str, reason: str) -> None:
        """Undo `code`'s withdrawal (audited)."""
        # lazy: study.protocol.corrections costs 6 ms at start-up
        from study.protocol.corrections import reinstate

        reinstate(self.engine, code, reason)

    def correct_group(self, code: str, group: str, reason: str) -> tuple[str, ...]:
        """Move `code` to `group` before their first trial (audited); the new order."""
        # lazy: study.protocol.corrections costs 6 ms at start-up
        from study.protocol.corrections import correct_group

        return correct_group(self.engine, code, group, reason, beyond_target=True)

    def add_participant(self, group: str) -> str:

        return add_participant(self.engine, group).code

    def analysis(self) -> Any:
        """`study.analysis.stats.Analysis` of everything stored."""
        # lazy: study.analysis.frames (with pandas, pyarrow, numpy) costs 0.4 s at start-up
        from study.analysis.frames import (
            participant_means,
            tlx_frame,
            trial_frame,
            without_withdrawn,
        )

        # lazy: study.analysis.stats (with numpy) costs 85 ms at start-up
        from study.analysis.stats import analyze

        trials, tlx, withdrawn = without_withdrawn(
            self.engine, trial_frame(self.engine), tlx_frame(self.engine)
        )
        if not len(trials) and not len(tlx):
            raise StudyInputError("the database holds no completed trials or questionnaires yet")
        return analyze(trials, participant_means(trials, tlx), withdrawn=withdrawn)

    def export_figures(
        self, folder: Path, formats: tuple[str, ...] = ("pdf", "svg", "png")
    ) -> list[Path]:
        # lazy: study.analysis.paper (with scipy, pandas, pyarrow) costs 1.5 s at start-up
        from study.analysis.paper import write_figures

        return write_figures(self.engine, folder, formats)


def calibrate_recording(
    recording: Path, model: str, progress: Progress = no_progress
) -> dict[str, Any]:
    """The calibration loop of `study calibrate` on one recording: its report.

    The same steps as the command (`BASE_MODELS[model].read`, `Calibrator.fit`,
    `report()`), without the files it writes; the app passes this into `make_app`.
    """
    # lazy: teleop_core.calibration (with scipy, statsmodels, pandas) costs 1.3 s at start-up
    from teleop_core.calibration import BASE_MODELS, Calibrator

    if model not in BASE_MODELS:
        from study.errors import StudyInputError

        raise StudyInputError(f"model {model!r}; expected one of {', '.join(BASE_MODELS)}")
    base = BASE_MODELS[model]
    calibrator = Calibrator(base).fit(
        base.read(recording),
        progress=progress,
    )
    return calibrator.report()


def load_shipped_estimator() -> ForceEstimator:
    """The estimator shipped with haptic-study, imported when first needed (its module
    loads torch); `study tui` passes this into `make_app`."""
    # lazy: study.protocol.default_estimator (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.protocol.default_estimator import load_estimator

    return load_estimator()
