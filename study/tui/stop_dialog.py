"""The stop dialog of the run screen: why a running trial is stopped, asked while it stands.

`x` holds the trial at once (`TrialRun.hold`: the session loop waits at its next step,
the samples so far committed) and opens `StopScreen`. Esc lets the trial go on; a reason
stops it (kept as interrupted, the reason in its audit row); Enter on an empty field
says a reason is needed. A trial can still end while the dialog is open (it was past
its last step when `x` came, or it failed): the screen's `trial_ended` turns the
question into whether to invalidate the trial it stored instead, so a stop asked for is
never dropped without a word.

The dialog only answers; the run screen acts on the answer (`StopAnswer`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.css.query import NoMatches
from textual.screen import ModalScreen
from textual.widgets import Input, Label

__all__ = ["StopAnswer", "StopScreen"]


@dataclass(frozen=True)
class StopAnswer:
    """What the operator chose: stop the running trial, or invalidate the stored one."""

    action: str
    """"stop" or "invalidate"."""
    reason: str
    trial_id: int | None = None
    """The stored trial to invalidate ("invalidate")."""


class StopScreen(ModalScreen[StopAnswer | None]):
    """Why the held trial is stopped; dismissed with a `StopAnswer`, or None (Esc)."""

    DEFAULT_CSS = """
    StopScreen { align: center middle; }
    StopScreen #stop-box { width: 64; height: auto; border: thick $warning; padding: 1 2;
                           background: $surface; }
    StopScreen #question { width: 100%; }
    StopScreen #stop-needs { color: $error; }
    StopScreen #stop-keys { color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, code: str, ended: tuple[int | None, bool, str] | None = None) -> None:
        super().__init__()
        self.code = code
        self._ended_at_open = ended
        """(trial id, measured, how) of the trial once it has ended."""
        self.ended: str | None = ended[2] if ended is not None else None
        """How the trial ended while the dialog was open (None: it stands held)."""
        self.trial_id: int | None = None
        """The stored trial the dialog now offers to invalidate, if any."""

    def compose(self) -> ComposeResult:
        with Vertical(id="stop-box"):
            yield Label(
                f"Stop {self.code}'s running trial? It stands held until answered (its "
                "samples so far kept); stopped, it is kept as interrupted and repeated "
                "later. Why?",
                id="question",
            )
            yield Input(id="reason-text", placeholder="reason", select_on_focus=False)
            yield Label("", id="stop-needs")
            yield Label("Enter: stop it    Esc: let it go on", id="stop-keys")

    def on_mount(self) -> None:
        if self.ended is not None:  # told before it was shown
            self._show_ended()

    def trial_ended(self, trial_id: int | None, measured: bool, how: str) -> None:
        """The trial ended before the dialog was answered: `trial_id` stored as `how`
        ("completed", or why not)."""
        self.ended = how
        self._ended_at_open = (trial_id, measured, how)
        try:
            self._show_ended()
        except NoMatches:  # not composed yet: shown when it is mounted
            pass

    def _show_ended(self) -> None:
        assert self._ended_at_open is not None
        trial_id, measured, how = self._ended_at_open
        self.query_one("#stop-needs", Label).update("")
        question = self.query_one("#question", Label)
        keys = self.query_one("#stop-keys", Label)
        if trial_id is not None and measured:
            self.trial_id = trial_id
            question.update(
                f"{self.code}'s trial ended before it was stopped: it is stored as "
                f"{how} (id {trial_id}). Invalidate it instead? Why?"
            )
            keys.update("Enter: invalidate it    Esc: keep it valid")
            return
        what = "a practice trial, not measured" if trial_id is not None else how
        question.update(
            f"{self.code}'s trial ended before it was stopped ({what}): nothing to stop."
        )
        self.query_one("#reason-text", Input).display = False
        keys.update("Enter or Esc: close")
        self.focus()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        reason = event.value.strip()
        if not reason:
            what = "invalidate it" if self.trial_id is not None else "stop it"
            needs = f"a reason is needed to {what} (Esc: "
            needs += "keep it valid)" if self.trial_id is not None else "let it go on)"
            self.query_one("#stop-needs", Label).update(needs)
            return
        if self.trial_id is not None:
            self.dismiss(StopAnswer("invalidate", reason, self.trial_id))
        elif self.ended is None:
            self.dismiss(StopAnswer("stop", reason))

    def key_enter(self) -> None:  # the field hidden: Enter closes as Esc does
        if self.ended is not None and self.trial_id is None:
            self.dismiss(None)

    def action_cancel(self) -> None:
        self.dismiss(None)
