"""The overview screen: groups filling up, sessions done, and what is next.

It shows a `Roster` the app loads in a worker; it never loads anything itself, so the
first paint waits for nothing but the one roster query (`study bench tui`).
"""

from __future__ import annotations

from typing import ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.widgets import DataTable, Static

from study.tui.ops import OpsMixin
from study.tui.services import Roster

__all__ = ["OverviewPane"]


def _bar(done: int, total: int, width: int = 20) -> str:
    """`done` of `total` in `width` cells, never more: past the total the bar is full."""
    filled = min(width, round(width * done / total)) if total > 0 else 0
    return "█" * filled + "░" * (width - filled)


def fill_text(enrolled: int, target: int) -> str:
    """`4 of 3 (over target)`: a group's fill in words, at or past its target said so."""
    if enrolled > target:
        return f"{enrolled} of {target} (over target)"
    return f"{enrolled} of {target}" + (" (full)" if enrolled == target else "")


class OverviewPane(OpsMixin, Vertical, can_focus=True):
    """Study name, group fill, session progress and the next things to do; `e` exports
    the data, `b` checks the database and backs it up (`study.tui.ops`)."""

    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("e", "export_data", "Export data"),
        Binding("b", "backup", "Check+backup"),
    ]

    DEFAULT_CSS = """
    OverviewPane { height: 1fr; }
    OverviewPane #study-title { text-style: bold; height: auto; }
    OverviewPane #groups { height: auto; max-height: 8; }
    OverviewPane #progress { height: auto; margin: 1 0 0 0; }
    OverviewPane #next-up { height: auto; border: round $primary-muted; }
    OverviewPane #ops-status { height: auto; color: $text-muted; }
    """

    _shown_once = False

    def compose(self) -> ComposeResult:
        yield Static("loading the study...", id="study-title")
        table: DataTable[str] = DataTable(id="groups", cursor_type="row", zebra_stripes=True)
        table.add_columns("group", "enrolled", "target", "fill")
        yield table
        yield Static("", id="progress")
        next_up = Static("", id="next-up")
        next_up.border_title = "what is next"
        yield next_up
        yield Static("e: export the data   b: end of day, check and back up", id="ops-status")

    def show(self, roster: Roster) -> None:
        if not self._shown_once:  # the first roster: the overview's keys (e, b) act at once
            self._shown_once = True
            if self.app.focused is None or type(self.app.focused).__name__ == "ContentTabs":
                self.focus()
        self.query_one("#study-title", Static).update(f"Study: {roster.study}")
        table = self.query_one("#groups", DataTable)
        table.clear()
        for group, fill in roster.groups.items():
            table.add_row(
                group,
                str(fill["enrolled"]),
                str(fill["target"]),
                _bar(fill["enrolled"], fill["target"], 16)
                + (" over target" if fill["enrolled"] > fill["target"] else ""),
                key=group,
            )
        planned = sum(r["trials_planned"] for r in roster.participants)
        completed = sum(r["trials_completed"] for r in roster.participants)
        answered = len(roster.answered)
        blocks = sum(len(r["blocks"]) for r in roster.participants)
        text = Text()
        text.append(
            f"Sessions done: {roster.sessions_done()} of {len(roster.participants)} enrolled"
            f" ({sum(f['target'] for f in roster.groups.values())} planned)\n"
        )
        text.append(f"Trials:        {completed} of {planned}  {_bar(completed, planned)}\n")
        text.append(f"NASA-TLX:      {answered} of {blocks} blocks")
        self.query_one("#progress", Static).update(text)
        self.query_one("#next-up", Static).update("\n".join(roster.what_next()))
