"""Screens over the current one: a yes/no question (`Confirm`: `y` answers yes, `n` or
Esc no), asked before what cannot be undone in a session (stopping a running trial,
quitting during one, enrolling past a group's target); and a text to read (`TextScreen`).
"""

from __future__ import annotations

from typing import ClassVar

from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Input, Label, Static

from study.protocol.free_text import MAX_TEXT_CHARS
from study.tui.char_count import CharCount


class Confirm(ModalScreen[bool]):
    """Dismissed with True (y) or False (n, Esc)."""

    DEFAULT_CSS = """
    Confirm { align: center middle; }
    Confirm #confirm { width: 60; height: auto; border: thick $warning; padding: 1 2;
                       background: $surface; }
    Confirm #question { width: 100%; }
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


class TextScreen(ModalScreen[None]):
    """A titled, scrollable text over the screen; Esc or q closes it."""

    DEFAULT_CSS = """
    TextScreen { align: center middle; }
    TextScreen #text-box { width: 90%; height: 80%; border: thick $primary; padding: 0 1;
                           background: $surface; }
    TextScreen #text-title { text-style: bold; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("escape", "close", "Close"),
        Binding("q", "close", "Close", show=False),
    ]

    def __init__(self, title: str, text: str) -> None:
        super().__init__()
        self.title_text = title
        self.text = text

    def compose(self) -> ComposeResult:
        with VerticalScroll(id="text-box"):
            yield Label(self.title_text, id="text-title")
            yield Static(self.text, id="text", markup=False)

    def action_close(self) -> None:
        self.dismiss(None)


class ReasonScreen(ModalScreen[str | None]):
    """A question answered with a line of text: Enter gives it (not empty), Esc cancels."""

    DEFAULT_CSS = """
    ReasonScreen { align: center middle; }
    ReasonScreen #reason-box { width: 64; height: auto; border: thick $warning; padding: 1 2;
                               background: $surface; }
    ReasonScreen #question { width: 100%; }
    ReasonScreen #reason-keys { color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "Cancel")]

    def __init__(
        self,
        question: str,
        placeholder: str = "reason",
        value: str = "",
        enter: str = "record it",
        limit: int | None = MAX_TEXT_CHARS,
    ) -> None:
        super().__init__()
        self.question = question
        self.placeholder = placeholder
        self.value = value
        """The text the field opens with (a note to read and add to, or one not kept)."""
        self.enter = enter
        """What Enter does, on the dialog's key line ("record it", "export there")."""
        self.limit = limit
        """The most characters the answer may have, counted below the field (None: no
        count, for a folder)."""

    def compose(self) -> ComposeResult:
        with Vertical(id="reason-box"):
            yield Label(self.question, id="question")
            # the cursor after the text, none of it selected: typing adds to it
            yield Input(
                self.value, id="reason-text", placeholder=self.placeholder, select_on_focus=False
            )
            if self.limit is not None:
                yield CharCount(self.value, self.limit, id="reason-count")
            yield Label(f"Enter: {self.enter}    Esc: cancel", id="reason-keys")

    def on_input_changed(self, event: Input.Changed) -> None:
        for count in self.query(CharCount):
            count.count(event.value)

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        if event.value.strip():
            self.dismiss(event.value.strip())

    def action_cancel(self) -> None:
        self.dismiss(None)
