"""The overview screen: groups filling up, sessions done, and what is next.

It shows a `Roster` the app loads in a worker; it never loads anything itself, so the
first paint waits for nothing but the one roster query (`study bench tui`).
"""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.widgets import DataTable, Static

from study.tui.services import Roster

__all__ = ["OverviewPane"]


def _bar(done: int, total: int, width: int = 20) -> str:
    filled = round(width * done / total) if total else 0
    return "█" * filled + "░" * (width - filled)


class OverviewPane(Vertical):
    """Study name, group fill, session progress and the next things to do."""

    DEFAULT_CSS = """
    OverviewPane { height: 1fr; }
    OverviewPane #study-title { text-style: bold; height: auto; }
    OverviewPane #groups { height: auto; max-height: 8; }
    OverviewPane #progress { height: auto; margin: 1 0 0 0; }
    OverviewPane #next-up { height: auto; border: round $primary-muted; }
    """

    def compose(self) -> ComposeResult:
        yield Static("loading the study...", id="study-title")
        table = DataTable(id="groups", cursor_type="row", zebra_stripes=True)
        table.add_columns("group", "enrolled", "target", "fill")
        yield table
        yield Static("", id="progress")
        next_up = Static("", id="next-up")
        next_up.border_title = "what is next"
        yield next_up

    def show(self, roster: Roster) -> None:
        self.query_one("#study-title", Static).update(f"Study: {roster.study}")
        table = self.query_one("#groups", DataTable)
        table.clear()
        for group, fill in roster.groups.items():
            table.add_row(
                group,
                str(fill["enrolled"]),
                str(fill["target"]),
                _bar(fill["enrolled"], fill["target"], 16),
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
