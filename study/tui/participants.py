"""The participants screen: enrol one into a group; the list with codes, orders and progress.

Enrolment is `study.protocol.roster.add_participant` in a worker (it takes the write
lock, which another lab machine may hold for a moment); the new code comes back as a
message and the app reloads the roster.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, Select

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
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("a", "add", "Add participant"),
        Binding("w", "withdraw", "Withdraw"),
        Binding("n", "note", "Note"),
        Binding("o", "session_note", "Session note"),
    ]

    @dataclass
    class Added(Message):
        """A participant was enrolled."""

        code: str
        group: str

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

    def compose(self) -> ComposeResult:
        with Horizontal(id="add-row"):
            yield Label("Group")
            yield Select[str]([], id="group", compact=True, prompt="group")
            yield Button("Add (a)", id="add", compact=True)
            yield Label("", id="add-status")
        with Horizontal(id="filter-row"):
            yield Label("Find ")
            yield Input(id="filter", placeholder="code, group or state (e.g. P01, expert, "
                        "withdrawn, done)", compact=True)  # fmt: skip
        table = DataTable(id="people", cursor_type="row", zebra_stripes=True)
        table.add_columns("code", "group", "order", "progress", "next")
        yield table

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
        table.clear()
        for r in roster.participants:
            nxt = roster.next_trial(r["code"])
            row = (
                r["code"],
                r["group"],
                " -> ".join(r["condition_order"]),
                f"{r['trials_completed']}/{r['trials_planned']}",
                (f"withdrawn: {r['withdrawn']}" if r.get("withdrawn")
                 else nxt.describe() if nxt else "done"),
            )
            if wanted and not any(wanted in str(cell).lower() for cell in row):
                continue
            table.add_row(*row, key=r["code"])

    @on(Input.Changed, "#filter")
    def _filter_changed(self, event: Input.Changed) -> None:
        event.stop()
        self._fill_table()

    @on(Button.Pressed, "#add")
    def _add_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.action_add()

    def action_add(self) -> None:
        group = self.query_one("#group", Select).value
        if group is Select.NULL:
            return
        fill = self._fill.get(str(group))
        if fill is not None and fill["enrolled"] >= fill["target"]:
            from study.tui.confirm import Confirm

            def answered(yes: bool | None) -> None:
                if yes:
                    self._start_enrolment(str(group))
                else:
                    self._status(f"not enrolled: the {group} group is full")

            self.app.push_screen(
                Confirm(f"The {group} group has its {fill['target']} participants. "
                        f"Enrol one more {group} all the same?"), answered,
            )  # fmt: skip
            return
        self._start_enrolment(str(group))

    def _under_cursor(self) -> str | None:
        table = self.query_one("#people", DataTable)
        return str(table.get_row_at(table.cursor_row)[0]) if table.row_count else None

    def action_note(self, session: bool = False) -> None:
        """A note on the participant under the cursor (replacing theirs) or, with
        `session`, on their session (added beside the others); both audited."""
        code = self._under_cursor()
        if code is None:
            return
        from study.tui.confirm import ReasonScreen

        what = f"a note on {code}'s session" if session else f"{code}'s note (it replaces theirs)"

        def answered(text: str | None) -> None:
            if text:
                self._note(code, text, session)

        self.app.push_screen(ReasonScreen(f"{what[0].upper()}{what[1:]}; no names or contact "
                                          "details:", "note"), answered)  # fmt: skip

    def action_session_note(self) -> None:
        self.action_note(session=True)

    @work(thread=True, group="note", exit_on_error=False)
    def _note(self, code: str, text: str, session: bool) -> None:
        try:
            self.services.note(code, text, session)
        except ValueError as exc:
            self.app.call_from_thread(self._status, f"refused: {exc}")
            return
        kind = "session note" if session else "note"
        self.app.call_from_thread(self._status, f"{code}: {kind} kept")

    def action_withdraw(self) -> None:
        """Withdraw the participant under the list's cursor, with a reason (audited)."""
        table = self.query_one("#people", DataTable)
        if table.row_count == 0:
            return
        code = str(table.get_row_at(table.cursor_row)[0])
        from study.tui.confirm import ReasonScreen

        def answered(reason: str | None) -> None:
            if reason:
                self._status(f"withdrawing {code}...")
                self._withdraw(code, reason)

        self.app.push_screen(
            ReasonScreen(f"Withdraw {code}? Their data are kept and marked, no more sessions "
                         "run, and the analysis leaves them out. Why?"), answered,
        )  # fmt: skip

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
        self.query_one("#add-status", Label).update(f"enrolling a {group}...")
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
        self._status(f"not enrolled: {line}" if group == "enrol" else f"not withdrawn: {line}")
        super().worker_failed(group, line)

    def _status(self, text: str) -> None:
        self.last_message = text
        self.query_one("#add-status", Label).update(text)
        self.refresh(layout=True)  # a long line wraps: the list below moves down

    @on(Added)
    def _added(self, event: Added) -> None:
        self._status(f"enrolled {event.code} ({event.group})")
