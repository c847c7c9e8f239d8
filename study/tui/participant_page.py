"""A participant's page: everything stored about them, and the audited corrections.

Opened with Enter on the participants list (F2), `v` on the run screen (F3) or from the
command palette. It shows the schedule in the participant's counterbalanced order
(blocks done and to come, each block's NASA-TLX stored or missing), every trial row
(attempts and interrupted ones, with why, completion time, success, peaks and
validity), the probes run and due, and the notes (the standing note and each added
note, with when and who). Its keys make the corrections, each asking for a reason that
goes into the audit log: `i` marks the highlighted measured trial invalid (or valid
again), `a` adds a note to the history, `e` edits the standing note, `u` undoes a
withdrawal, `g` corrects the group before the first trial. Esc goes back.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.screen import ModalScreen, Screen
from textual.widgets import DataTable, Footer, Input, Label, Select, Static

from study.protocol.tasks import Measure, get_task, is_task
from study.tui.db_errors import SafeWorkers

if TYPE_CHECKING:
    from study.protocol.participant_record import ParticipantRecord, TrialRow
    from study.tui.services import StudyServices

__all__ = ["GroupScreen", "ParticipantPage", "schedule_line", "trial_cells", "trial_detail"]

NOTES_SHOWN = 4
"""Notes listed under the trials (the newest); all of them are in the audit log."""


def _shown_measures(t: TrialRow) -> list[Measure]:
    """The stored measures of `t` in its task's order, as the task declares them (a
    task no longer registered: its stored names, unlabelled)."""
    declared = {m.name: m for m in get_task(t.task).measures} if is_task(t.task) else {}
    return [declared.get(n) or Measure(n, "", n, "", analysed=False) for n in t.measures]


def trial_cells(t: TrialRow) -> tuple[str, ...]:
    """One row of the page's trial table. The cells are short, so that 80 columns hold
    them all with a four-digit id: the trial is its number (`p2`: practice trial 2),
    the peaks are the forces the analysis compares (the others are in the detail line
    under the table), and validity is the last column."""
    forces = [m.name for m in _shown_measures(t) if m.unit == "N" and m.analysed]
    measured = t.status == "completed" and not t.practice
    return (
        str(t.id),
        f"{t.block_index + 1} {t.task}/{t.condition}",
        f"p{t.number}" if t.practice else str(t.number),
        str(t.attempt),
        t.status,
        "-" if t.completion_time_s is None else f"{t.completion_time_s:.1f}",
        "-" if t.success is None else ("yes" if t.success else "no"),
        "/".join(f"{t.measures[n]:.2f}" for n in forces) or "-",
        ("NO" if t.invalid_reason else "yes") if measured else "-",
    )


def trial_detail(t: TrialRow) -> str:
    """The highlighted trial in full: why it was interrupted, validity, every measure
    by its label (a line of its own)."""
    line = f"trial {t.id}, {t.task}/{t.condition} {t.label()}, attempt {t.attempt}: {t.status}"
    if t.why and t.status in ("interrupted", "aborted"):
        line += f" ({t.why})"
    if t.completion_time_s is not None:
        line += f" in {t.completion_time_s:.2f} s"
    if t.success is not None:
        line += ", success" if t.success else ", no success"
    if t.invalid_reason:
        line += f"; INVALID: {t.invalid_reason}"
    measures = ", ".join(
        f"{m.label} {t.measures[m.name]:.3g}{' ' + m.unit if m.unit else ''}"
        for m in _shown_measures(t)
    )
    return f"{line}\n{measures}" if measures else line


def schedule_line(record: ParticipantRecord) -> str:
    """The blocks in the participant's order: done, next, to come, and each TLX."""
    nxt = record.next_block()
    parts = []
    for b in record.blocks:
        mark = "next " if nxt is not None and b.block_index == nxt.block_index else ""
        tlx = f" TLX {b.tlx}" if b.tlx != "-" else ""
        parts.append(
            f"{mark}{b.block_index + 1} {b.task}/{b.condition} {b.completed}/{b.planned}{tlx}"
        )
    return "schedule: " + ", ".join(parts) if parts else "schedule: none"


class GroupScreen(ModalScreen[tuple[str, str] | None]):
    """The right group and why: Enter in the reason field records it, Esc cancels."""

    DEFAULT_CSS = """
    GroupScreen { align: center middle; }
    GroupScreen #group-box { width: 64; height: auto; border: thick $warning; padding: 1 2;
                             background: $surface; }
    GroupScreen #question { width: 100%; }
    GroupScreen #group-keys { color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, question: str, groups: list[str]) -> None:
        super().__init__()
        self.question = question
        self.groups = groups

    def compose(self) -> ComposeResult:
        with Vertical(id="group-box"):
            yield Label(self.question, id="question")
            yield Select[str](  # the first other group at once: one group, no choosing
                [(g, g) for g in self.groups], id="new-group", compact=True, allow_blank=False
            )
            yield Input(id="group-reason", placeholder="reason")
            yield Label("Tab: next field    Enter: record it    Esc: cancel", id="group-keys")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        group = self.query_one("#new-group", Select).value
        if event.value.strip() and group is not Select.NULL:
            self.dismiss((str(group), event.value.strip()))

    def action_cancel(self) -> None:
        self.dismiss(None)


class ParticipantPage(SafeWorkers, Screen[None]):
    """One participant: schedule, trials, probes, notes; the corrections."""

    DEFAULT_CSS = """
    ParticipantPage { layout: vertical; }
    ParticipantPage #who { height: auto; text-style: bold; padding: 0 1; }
    ParticipantPage #schedule, ParticipantPage #probes { height: auto; padding: 0 1; }
    ParticipantPage #trials { height: 1fr; }
    ParticipantPage #trial-detail { height: auto; max-height: 7; padding: 0 1; }
    ParticipantPage #notes { height: auto; max-height: 6; padding: 0 1; color: $text-muted; }
    ParticipantPage #page-status { width: 100%; height: auto; padding: 0 1; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("escape", "back", "Back"),
        Binding("i", "validity", "Validity"),
        Binding("a", "add_note", "Add note"),
        Binding("e", "edit_note", "Edit note"),
        Binding("u", "reinstate", "Reinstate"),
        Binding("g", "group", "Group"),
    ]

    def __init__(self, services: StudyServices, code: str, groups: list[str]) -> None:
        super().__init__()
        self.services = services
        self.code = code
        self.groups = groups
        self.record: ParticipantRecord | None = None
        self.last_message = ""

    def compose(self) -> ComposeResult:
        yield Label(f"{self.code}: loading...", id="who")
        yield Static("", id="schedule", markup=False)
        yield Static("", id="probes", markup=False)
        table: DataTable[str] = DataTable(id="trials", cursor_type="row", zebra_stripes=True)
        table.add_columns(
            "id", "block", "trial", "att", "status", "time s", "ok", "peaks N", "valid"
        )
        yield table
        yield Static("", id="trial-detail", markup=False)
        yield Static("", id="notes", markup=False)
        yield Label("", id="page-status")
        yield Footer(compact=True, show_command_palette=False)  # every key fits at 80

    def on_mount(self) -> None:
        self.query_one("#trials", DataTable).focus()
        self.reload()

    # -- reading --------------------------------------------------------------------------

    def reload(self) -> None:
        self._load()

    @work(thread=True, exclusive=True, group="record", exit_on_error=False)
    def _load(self) -> None:
        record = self.services.participant_record(self.code)
        self.app.call_from_thread(self._show, record)

    def _show(self, record: ParticipantRecord) -> None:
        self.record = record
        state = f"withdrawn: {record.withdrawn}" if record.withdrawn else "in the study"
        site = f", site {record.site}" if record.site else ""
        self.query_one("#who", Label).update(
            f"{record.code} ({record.group}{site}): conditions "
            f"{' -> '.join(record.condition_order)}; {state}"
        )
        self.query_one("#schedule", Static).update(schedule_line(record))
        probes = ", ".join(f"{k} {n} trials" for k, n in record.probes.items()) or "none run"
        due = f"; due: {', '.join(record.probes_due)}" if record.probes_due else ""
        self.query_one("#probes", Static).update(f"probes: {probes}{due}")
        table = self.query_one("#trials", DataTable)
        kept = table.cursor_row
        table.clear()
        for t in record.trials:
            table.add_row(*trial_cells(t), key=str(t.id))
        if record.trials:
            table.move_cursor(row=min(kept, len(record.trials) - 1))
        self._show_detail()
        lines = [f"note: {record.note or '(none)'}"]
        for n in record.notes[-NOTES_SHOWN:]:
            kind = "added" if n.kind == "session" else "note set"
            lines.append(f"{n.at:%Y-%m-%d %H:%M} {n.actor or '?'} {kind}: {n.text}")
        if len(record.notes) > NOTES_SHOWN:
            lines.insert(1, f"({len(record.notes) - NOTES_SHOWN} older notes in the audit log)")
        self.query_one("#notes", Static).update("\n".join(lines))
        self.refresh_bindings()

    @on(DataTable.RowHighlighted, "#trials")
    def _highlighted(self, event: DataTable.RowHighlighted) -> None:
        event.stop()
        self._show_detail()

    def _show_detail(self) -> None:
        t = self.highlighted_trial()
        self.query_one("#trial-detail", Static).update(
            trial_detail(t) if t is not None else "no trials stored"
        )

    def _status(self, text: str) -> None:
        self.last_message = text
        self.query_one("#page-status", Label).update(text)

    def highlighted_trial(self) -> TrialRow | None:
        table = self.query_one("#trials", DataTable)
        if self.record is None or not table.row_count:
            return None
        key = str(table.get_row_at(table.cursor_row)[0])
        return next((t for t in self.record.trials if str(t.id) == key), None)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        """Undo only for a withdrawn participant (the group key stays: once a trial is
        stored it says in one line why the group cannot change)."""
        record = self.record
        if action == "reinstate":
            return record is not None and record.withdrawn is not None
        return True

    # -- corrections ----------------------------------------------------------------------

    def _ask(self, question: str, then, value: str = "", placeholder: str = "reason") -> None:
        # lazy: study.tui.confirm costs 4 ms at start-up
        from study.tui.confirm import ReasonScreen

        def answered(text: str | None) -> None:
            if text:
                then(text)

        self.app.push_screen(ReasonScreen(question, placeholder, value), answered)

    def action_back(self) -> None:
        self.dismiss(None)

    def action_validity(self) -> None:
        t = self.highlighted_trial()
        if t is None:
            return
        if t.practice or t.status != "completed":
            state = "a practice trial" if t.practice else t.status
            self._status(f"trial {t.id} is {state}; only a completed measured trial is marked")
            return
        valid = t.invalid_reason is not None
        what = f"{t.task}/{t.condition} {t.label()} (id {t.id})"
        question = (
            f"Count {self.code}'s {what} again in the analysis? Why?"
            if valid
            else f"Mark {self.code}'s {what} invalid? It is kept and left out of the "
            "analysis, with the reason. Why?"
        )
        self._ask(question, lambda reason: self._mark(t.id, valid, reason))

    @work(thread=True, group="correct", exit_on_error=False)
    def _mark(self, trial_id: int, valid: bool, reason: str) -> None:
        what = self.services.mark_trial(trial_id, valid, reason)
        done = "valid again" if valid else "marked invalid"
        self.app.call_from_thread(self._changed, f"trial {trial_id} ({what}) {done} ({reason})")

    def action_add_note(self) -> None:
        self._ask(
            f"A note on {self.code}, added to their notes (no names or contact details):",
            lambda text: self._note(text, True),
            placeholder="note",
        )

    def action_edit_note(self) -> None:
        note = self.record.note if self.record is not None else None
        self._ask(
            f"{self.code}'s standing note (edit it or add to it; the old one stays in the "
            "audit log):",
            lambda text: self._note(text, False),
            value=note or "",
            placeholder="note",
        )

    @work(thread=True, group="correct", exit_on_error=False)
    def _note(self, text: str, added: bool) -> None:
        self.services.note(self.code, text, added)
        self.app.call_from_thread(
            self._changed, f"{self.code}: note {'added' if added else 'kept'}"
        )

    def action_reinstate(self) -> None:
        if self.record is None or self.record.withdrawn is None:
            return
        self._ask(
            f"Undo {self.code}'s withdrawal ({self.record.withdrawn})? They continue where "
            "they stopped and the analysis counts them. Why?",
            self._reinstate,
        )

    @work(thread=True, group="correct", exit_on_error=False)
    def _reinstate(self, reason: str) -> None:
        self.services.reinstate(self.code, reason)
        self.app.call_from_thread(self._changed, f"{self.code} is in the study again ({reason})")

    def action_group(self) -> None:
        record = self.record
        if record is None:
            return
        if record.trials or record.probes:
            self._status(
                f"{self.code} has trials stored: the group can be corrected only before the "
                "first trial"
            )
            return
        others = [g for g in self.groups if g != record.group]

        def answered(choice: tuple[str, str] | None) -> None:
            if choice is not None:
                self._regroup(*choice)

        self.app.push_screen(
            GroupScreen(
                f"{self.code} is in the {record.group} group. The right group, and why "
                "(they take its next counterbalanced order)?",
                others,
            ),
            answered,
        )

    @work(thread=True, group="correct", exit_on_error=False)
    def _regroup(self, group: str, reason: str) -> None:
        order = self.services.correct_group(self.code, group, reason)
        self.app.call_from_thread(
            self._changed, f"{self.code} moved to {group}: conditions {' then '.join(order)}"
        )

    def _changed(self, line: str) -> None:
        self._status(line)
        self.reload()
        reload = getattr(self.app, "reload", None)
        if reload is not None:  # the other screens' roster
            reload()

    def worker_failed(self, group: str, line: str) -> None:
        self._status(f"{'not changed' if group == 'correct' else 'not read'}: {line}")
        super().worker_failed(group, line)
