"""A yes/no question over the current screen: `y` answers yes, `n` or Esc no.

Asked before what cannot be undone in a session: stopping a running trial, quitting
during one, enrolling past a group's target.
"""

from __future__ import annotations

from typing import ClassVar

from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Label


class Confirm(ModalScreen[bool]):
    """Dismissed with True (y) or False (n, Esc)."""

    DEFAULT_CSS = """
    Confirm { align: center middle; }
    Confirm #confirm { width: 60; height: auto; border: thick $warning; padding: 1 2;
                       background: $surface; }
    Confirm #keys { padding-top: 1; color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n", "answer(False)", "No"),
        Binding("escape", "answer(False)", "No", show=False),
    ]

    def __init__(self, question: str) -> None:
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        with Vertical(id="confirm"):
            yield Label(self.question, id="question")
            yield Label("y: yes    n or Esc: no", id="keys")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)
