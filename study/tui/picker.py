"""The run screen's participant picker: every participant with group, progress and next
trial (task/condition, block), searched by code or group as it is typed.

`ParticipantSelect` is the run screen's `Select` of codes whose Enter (or a click) opens
`ParticipantPicker` over the screen instead of the plain list: the search field has the
focus, Up/Down move through the matching rows, Enter picks the highlighted one (the first
match once something is typed), Esc leaves the choice as it was. The value is still the code, so
everything that reads or sets the Select works as before.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from textual import on
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import DataTable, Input, Label, Select
from textual.widgets._select import SelectCurrent

if TYPE_CHECKING:
    from study.tui.services import Roster

__all__ = ["ParticipantPicker", "ParticipantSelect", "picker_rows"]

KEEP = "-keep-"
"""The row key of the picker's first row, which leaves the choice as it is."""


def picker_rows(roster: Roster) -> list[tuple[str, str, str, str]]:
    """(code, group, progress, next) of every participant, in the roster's order."""
    rows = []
    for r in roster.participants:
        nxt = roster.next_trial(r["code"])
        if r.get("withdrawn"):
            what = f"withdrawn: {r['withdrawn']}"
        elif nxt is None:
            what = "done"
        else:
            what = f"{nxt.describe()}, block {nxt.block_index + 1}"
        progress = f"{r['trials_completed']}/{r['trials_planned']}"
        rows.append((r["code"], r["group"], progress, what))
    return rows


class ParticipantPicker(ModalScreen[str | None]):
    """Dismissed with the picked code, or None (Esc)."""

    DEFAULT_CSS = """
    ParticipantPicker { align: center middle; }
    ParticipantPicker #picker-box { width: 76; max-width: 100%; height: 80%;
                                    border: thick $primary; background: $surface; }
    ParticipantPicker #picker-table { height: 1fr; }
    ParticipantPicker #picker-keys { color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("escape", "cancel", "Cancel"),
        Binding("down", "move(1)", "Down", show=False, priority=True),
        Binding("up", "move(-1)", "Up", show=False, priority=True),
    ]

    def __init__(self, rows: list[tuple[str, str, str, str]], current: str | None) -> None:
        super().__init__()
        self.rows = rows
        self.current = current

    def compose(self) -> ComposeResult:
        with Vertical(id="picker-box"):
            yield Input(id="picker-search", placeholder="search: code or group (e.g. P01)")
            table: DataTable[str] = DataTable(
                id="picker-table", cursor_type="row", zebra_stripes=True
            )
            table.add_columns("code", "group", "done", "next trial")
            yield table
            yield Label("type to search  Up/Down: move  Enter: pick  Esc: cancel", id="picker-keys")

    def on_mount(self) -> None:
        self._fill("")
        table = self.query_one("#picker-table", DataTable)
        if self.current is not None and self.current in table.rows:
            table.move_cursor(row=table.get_row_index(self.current))
        self.query_one("#picker-search", Input).focus()

    def matching(self, text: str) -> list[tuple[str, str, str, str]]:
        """The rows whose code starts with `text`, then those whose code or group holds it
        (any case)."""
        wanted = text.strip().lower()
        if not wanted:
            return list(self.rows)
        first = [r for r in self.rows if r[0].lower().startswith(wanted)]
        more = [r for r in self.rows if r not in first and (wanted in f"{r[0]} {r[1]}".lower())]
        return first + more

    def _fill(self, text: str) -> None:
        """The matching rows; without a search, a first row that keeps the choice as it
        is (as the plain list's prompt did: Enter, Down, Enter still picks the first)."""
        table = self.query_one("#picker-table", DataTable)
        table.clear()
        if not text.strip():
            table.add_row("-", "", "", "(no change)", key=KEEP)
        rows = self.matching(text)
        for row in rows:
            table.add_row(*row, key=row[0])
        if text.strip() and not rows:  # said, not an empty list (Enter keeps the choice)
            table.add_row("-", "", "", f"no participant {_quoted(text.strip())}", key=KEEP)
        if table.row_count:
            table.move_cursor(row=0)

    @on(Input.Changed, "#picker-search")
    def _searched(self, event: Input.Changed) -> None:
        event.stop()
        self._fill(event.value)

    def action_move(self, step: int) -> None:
        table = self.query_one("#picker-table", DataTable)
        if table.row_count:
            table.move_cursor(row=max(0, min(table.row_count - 1, table.cursor_row + step)))

    @on(Input.Submitted, "#picker-search")
    def _submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self._pick()

    @on(DataTable.RowSelected, "#picker-table")
    def _selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        self._pick()

    def _pick(self) -> None:
        table = self.query_one("#picker-table", DataTable)
        if table.row_count:
            key = table.coordinate_to_cell_key(table.cursor_coordinate).row_key.value
            self.dismiss(None if key == KEEP else key)

    def action_cancel(self) -> None:
        self.dismiss(None)


class ParticipantSelect(Select[str]):
    """The run screen's participant `Select`, which opens `ParticipantPicker` instead of
    its own list (the screen hands it the roster's rows with `rows`)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.rows: list[tuple[str, str, str, str]] = []

    def action_show_overlay(self) -> None:
        if not self.rows:
            return

        def picked(code: str | None) -> None:
            if code is not None:
                self.value = code
            self.focus()

        current = None if self.value is Select.NULL else str(self.value)
        self.app.push_screen(ParticipantPicker(self.rows, current), picked)

    @on(SelectCurrent.Toggle)
    def _open(self, event: SelectCurrent.Toggle) -> None:
        """A click on the field: the picker, not the plain list."""
        event.stop()
        event.prevent_default()
        self.action_show_overlay()


def _quoted(text: str, limit: int = 40) -> str:
    """`text` as typed, cut to `limit` characters (a paste does not fill the row)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."
