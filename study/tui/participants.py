"""The participants screen: enrol one into a group; the list with codes, orders and progress.

A person types words here (the Find field's codes, groups and states), so no action is
on a key that can be typed: a printable key on the list goes into the Find field, and
enrolling, withdrawing and the notes are on ctrl keys (each still asks before acting).

Enrolment is `study.protocol.roster.add_participant` in a worker (it takes the write
lock, which another lab machine may hold for a moment); the new code comes back as a
message and the app reloads the roster.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from textual import events, on, work
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, Select, Static

from study.tui.db_errors import SafeWorkers
from study.tui.services import Roster, StudyServices

__all__ = ["ParticipantsPane"]


class ParticipantsPane(SafeWorkers, Vertical):
    """Add a participant; list everyone with code, group, order and progress."""

    DEFAULT_CSS = """
    ParticipantsPane { height: 1fr; }
    ParticipantsPane #add-row { height: auto; }
    ParticipantsPane #filter-row { height: 1; }
    ParticipantsPane #filter { width: 1fr; }
    ParticipantsPane #add-row Label { padding: 0 1; }
    ParticipantsPane #add-status { width: 1fr; }
    ParticipantsPane #group { width: 24; }
    ParticipantsPane #people { height: 1fr; }
    ParticipantsPane #detail { height: auto; max-height: 4; color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("ctrl+a", "add", "Enrol"),
        Binding("ctrl+w", "withdraw", "Withdraw"),
        Binding("ctrl+n", "note", "Note"),
        Binding("ctrl+o", "session_note", "Session note"),
    ]
    """Keys no typed word holds (in the Find field ctrl+a and ctrl+w edit the text)."""

    @dataclass
    class Added(Message):
        """A participant was enrolled."""

        code: str
        group: str

    @dataclass
    class NoteKept(Message):
        code: str

    @dataclass
    class Withdrawn(Message):
        """A participant was withdrawn."""

        code: str

    def __init__(self, services: StudyServices, **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self.services = services
        self.last_message = ""
        self._groups: list[str] = []
        self._fill: dict[str, dict[str, int]] = {}
        self._roster: Roster | None = None
        self._unsent: dict[tuple[str, bool], str] = {}
        """(code, session note?) -> a note the database refused, offered again."""
        self._note_sent: tuple[str, bool] = ("", False)
        """(code, session note?) of the note last handed to the database."""

    def compose(self) -> ComposeResult:
        with Horizontal(id="add-row"):
            yield Label("Group")
            yield Select[str]([], id="group", compact=True, prompt="group")
            yield Button("Add (^a)", id="add", compact=True)
            yield Label("", id="add-status")
        with Horizontal(id="filter-row"):
            yield Label("Find ")
            yield Input(
                id="filter",
                placeholder="code, group or state (e.g. P01, expert, withdrawn, done)",
                compact=True,
                select_on_focus=False,  # a letter typed on the list adds to the word
            )
        table: DataTable[str] = DataTable(id="people", cursor_type="row", zebra_stripes=True)
        table.add_columns("code", "group", "order", "progress", "next")
        yield table
        yield Static("", id="detail")

    def focus_first(self) -> None:
        """F2: the list, so that its keys (ctrl+a/w/n/o) and the arrows act at once."""
        self.query_one("#people", DataTable).focus()

    def on_key(self, event: events.Key) -> None:
        """A printable key on the list goes into the Find field: a typed word searches,
        and opens no dialog. The app's keys (`?`, the digits 1-6 of the screens) stay
        theirs while the field is empty; once a word is begun they are part of it (the
        list still has the focus for the keys typed quickly after the first: `P01`)."""
        if not (event.is_printable and event.character):
            return
        find = self.query_one("#filter", Input)
        if not isinstance(self.app.focused, DataTable):
            return
        if event.key in self.app.active_bindings and not find.value:
            return
        event.stop()
        event.prevent_default()
        find.focus()
        find.cursor_position = len(find.value)
        find.insert_text_at_cursor(event.character)

    def show(self, roster: Roster) -> None:
        self._roster = roster
        self._fill = roster.groups
        groups = list(roster.groups)
        if groups != self._groups:
            self._groups = groups
            select = self.query_one("#group", Select)
            select.set_options([(g, g) for g in groups])
            if groups:
                select.value = groups[0]
        self._fill_table()

    def _fill_table(self) -> None:
        """The list, with only the rows that match the Find field (any column, any case)."""
        roster = self._roster
        if roster is None:
            return
        wanted = self.query_one("#filter", Input).value.strip().lower()
        table = self.query_one("#people", DataTable)
        kept = self._under_cursor()  # the cursor stays on its participant over a reload
        table.clear()
        for r in roster.participants:
            nxt = roster.next_trial(r["code"])
            row = (
                r["code"],
                r["group"],
                " -> ".join(r["condition_order"]),
                f"{r['trials_completed']}/{r['trials_planned']}",
                (
                    f"withdrawn: {r['withdrawn']}"
                    if r.get("withdrawn")
                    else nxt.describe()
                    if nxt
                    else "done"
                ),
            )
            if wanted and not any(wanted in str(cell).lower() for cell in row):
                continue
            table.add_row(*row, key=r["code"])
        if kept is not None and kept in table.rows:
            table.move_cursor(row=table.get_row_index(kept))
        self._show_detail()

    @on(DataTable.RowHighlighted, "#people")
    def _highlighted(self, event: DataTable.RowHighlighted) -> None:
        event.stop()
        self._show_detail()

    @on(DataTable.RowSelected, "#people")
    def _selected(self, event: DataTable.RowSelected) -> None:
        """Enter on a participant: their page (trials, notes, corrections)."""
        event.stop()
        code = self._under_cursor()
        if code is not None:
            self.app.open_participant(code)  # type: ignore[attr-defined]

    def _show_detail(self) -> None:
        """The participant under the cursor: their note, blocks and questionnaires."""
        code = self._under_cursor()
        row = self._row(code) if code is not None else None
        detail = self.query_one("#detail", Static)
        if row is None or self._roster is None:
            detail.update("")
            return
        answered = self._roster.answered
        blocks = []
        for b in row["blocks"]:
            tlx = (
                "TLX stored"
                if (code, b["task"], b["condition"]) in answered
                else ("TLX due" if b["completed"] >= b["planned"] else "")
            )
            blocks.append(
                f"{b['task']}/{b['condition']} {b['completed']}/{b['planned']}"
                + (f" {tlx}" if tlx else "")
            )
        lines = [
            f"{code} ({row['group']}): " + ", ".join(blocks),
            f"note: {row.get('note') or '(none)'}",
        ]
        if row.get("withdrawn"):
            lines.append(f"withdrawn: {row['withdrawn']}")
        detail.update("\n".join(lines))

    @on(Input.Changed, "#filter")
    def _filter_changed(self, event: Input.Changed) -> None:
        event.stop()
        self._fill_table()

    @on(Button.Pressed, "#add")
    def _add_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.action_add()

    def action_add(self) -> None:
        """Enrol one more of the chosen group; past the group's target (as the database
        has it now, whoever enrolled meanwhile) asked first."""
        group = self.query_one("#group", Select).value
        if group is Select.NULL:
            return
        self.query_one("#add-status", Label).update(f"enrolling one more {group}...")
        self._fresh_fill(str(group))

    @work(thread=True, exclusive=True, group="enrol", exit_on_error=False)
    def _fresh_fill(self, group: str) -> None:
        roster = self.services.roster()
        self.app.call_from_thread(self._enrol_or_ask, group, roster)

    def _enrol_or_ask(self, group: str, roster: Roster) -> None:
        self.app.show_roster(roster)  # type: ignore[attr-defined]
        fill = roster.groups.get(group)
        if fill is not None and fill["enrolled"] >= fill["target"]:
            from study.tui.confirm import Confirm
            from study.tui.overview import fill_text

            def answered(yes: bool | None) -> None:
                if yes:
                    self._start_enrolment(group)
                else:
                    self._status(f"not enrolled: the {group} group is full")

            self.app.push_screen(
                Confirm(
                    f"The {group} group is at {fill_text(fill['enrolled'], fill['target'])}. "
                    f"Enrol one more {group} all the same?"
                ),
                answered,
            )
            return
        self._start_enrolment(group)

    def _under_cursor(self) -> str | None:
        table = self.query_one("#people", DataTable)
        return str(table.get_row_at(table.cursor_row)[0]) if table.row_count else None

    def action_note(self, session: bool = False) -> None:
        """A note on the participant under the cursor (replacing theirs) or, with
        `session`, on their session (added beside the others); both audited."""
        code = self._under_cursor()
        if code is None:
            return
        # lazy: study.tui.confirm costs 5 ms at start-up
        from study.tui.confirm import ReasonScreen

        if session:
            what = f"A note on {code}'s session (added beside the others)"
            value = self._unsent.get((code, True), "")
        else:
            what = f"{code}'s note (as it stands: edit it or add to it)"
            row = self._row(code)
            value = self._unsent.get((code, False), (row or {}).get("note") or "")

        def answered(text: str | None) -> None:
            if text:
                self._unsent[(code, session)] = text  # until the database has it
                self._note(code, text, session)

        self.app.push_screen(
            ReasonScreen(f"{what}; no names or contact details:", "note", value), answered
        )

    def _row(self, code: str) -> dict | None:
        rows = self._roster.participants if self._roster is not None else []
        return next((r for r in rows if r["code"] == code), None)

    def _reopen_note(self, code: str, session: bool) -> None:
        """The note dialog again on `code`, holding the text the database refused."""
        table = self.query_one("#people", DataTable)
        codes = [str(table.get_row_at(k)[0]) for k in range(table.row_count)]
        # lazy: study.tui.confirm costs 5 ms at start-up
        from study.tui.confirm import ReasonScreen

        if code in codes and not isinstance(self.app.screen, ReasonScreen):
            table.move_cursor(row=codes.index(code))
            self.action_note(session)

    def action_session_note(self) -> None:
        self.action_note(session=True)

    @work(thread=True, group="note", exit_on_error=False)
    def _note(self, code: str, text: str, session: bool) -> None:
        self._note_sent = (code, session)
        try:
            self.services.note(code, text, session)
        except ValueError as exc:
            self.app.call_from_thread(self._status, f"refused: {exc}")
            return
        kind = "session note" if session else "note"
        self._unsent.pop((code, session), None)
        self.app.call_from_thread(self._status, f"{code}: {kind} kept")
        self.post_message(self.NoteKept(code))  # the app reloads the roster

    def action_withdraw(self) -> None:
        """Withdraw the participant under the list's cursor, with a reason (audited)."""
        table = self.query_one("#people", DataTable)
        if table.row_count == 0:
            return
        code = str(table.get_row_at(table.cursor_row)[0])
        # lazy: study.tui.confirm costs 5 ms at start-up
        from study.tui.confirm import ReasonScreen

        def answered(reason: str | None) -> None:
            if reason:
                self._status(f"withdrawing {code}...")
                self._withdraw(code, reason)

        self.app.push_screen(
            ReasonScreen(
                f"Withdraw {code}? Their data are kept and marked, no more sessions "
                "run, and the analysis leaves them out. Why?"
            ),
            answered,
        )

    @work(thread=True, exclusive=True, group="withdraw", exit_on_error=False)
    def _withdraw(self, code: str, reason: str) -> None:
        try:
            self.services.withdraw(code, reason)
        except ValueError as exc:
            self.app.call_from_thread(self._status, f"refused: {exc}")
            return
        self.app.call_from_thread(self._status, f"withdrew {code} ({reason})")
        self.post_message(self.Withdrawn(code))  # the app reloads the roster

    def _start_enrolment(self, group: str) -> None:
        self.query_one("#add-status", Label).update(f"enrolling one more {group}...")
        self._enrol(group)

    @work(thread=True, exclusive=True, group="enrol", exit_on_error=False)
    def _enrol(self, group: str) -> None:
        try:
            code = self.services.add_participant(group)
        except ValueError as exc:
            self.app.call_from_thread(self._status, f"refused: {exc}")
            return
        self.post_message(self.Added(code, group))

    def worker_failed(self, group: str, line: str) -> None:
        failed = {"enrol": "not enrolled", "withdraw": "not withdrawn"}
        if group == "note":  # the dialog comes back with what was typed
            line = f"note not kept: {line}; it is open again as typed (Esc: keep it for later)"
            code, session = self._note_sent
            if self._row(code) is not None:
                self.call_after_refresh(self._reopen_note, code, session)
        else:
            line = f"{failed.get(group, 'failed')}: {line}"
        self._status(line)
        super().worker_failed(group, line)

    def _status(self, text: str) -> None:
        self.last_message = text
        self.query_one("#add-status", Label).update(text)
        self.refresh(layout=True)  # a long line wraps: the list below moves down

    @on(Added)
    def _added(self, event: Added) -> None:
        self._status(f"enrolled {event.code} ({event.group})")
