"""The run screen's stop dialog: `x` holds the running trial and asks why it stops.

The trial is held at once (`TrialRun.hold`: its loop waits between two steps, the
samples so far committed, its clock standing), so however long the reason takes to
type, nothing of the trial runs meanwhile. Enter with a reason stops it (stored
`interrupted`, the reason in its audit row); Enter with no reason says what is needed;
Esc lets it go on where it stood. A trial that ended before the hold reached it (it was
at its very last step) is not lost silently: the dialog says how it ended and, for a
completed measured trial, asks whether to mark it invalid instead, with the same reason.
"""

from __future__ import annotations

from typing import ClassVar, Literal

from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Label

from study.tui.trial_runner import TrialOutcome

StopAnswer = tuple[Literal["stop", "invalidate"], str]
"""("stop", reason): stop the held trial; ("invalidate", reason): mark the trial that
ended meanwhile invalid. None (Esc): let the trial go on, or keep the ended one."""

NO_REASON = "a reason is needed: it goes into the audit log (Esc: {escape})"


class StopTrial(ModalScreen[StopAnswer | None]):
    """Why the held trial of `code` stops; Esc lets it go on."""

    DEFAULT_CSS = """
    StopTrial { align: center middle; }
    StopTrial #stop-box { width: 64; height: auto; border: thick $warning; padding: 1 2;
                          background: $surface; }
    StopTrial #question { width: 100%; }
    StopTrial #stop-needed { color: $error; }
    StopTrial #stop-keys { color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, code: str) -> None:
        super().__init__()
        self.code = code
        self.mode: Literal["stop", "invalidate", "ended"] = "stop"
        """What Enter does now: stop the held trial, invalidate the one that ended
        meanwhile, or (a trial that cannot be invalidated ended) only close."""
        self.trial_id: int | None = None
        """The trial that ended before it could be stopped (mode "invalidate")."""

    def compose(self) -> ComposeResult:
        with Vertical(id="stop-box"):
            yield Label(
                f"{self.code}'s trial is held (its clock stands). Stop it? It is kept as "
                "interrupted and repeated later. Why?",
                id="question",
            )
            yield Input(id="stop-reason", placeholder="reason", select_on_focus=False)
            yield Label("", id="stop-needed")
            yield Label("Enter: stop it    Esc: let it go on", id="stop-keys")

    def trial_ended(self, outcome: TrialOutcome, practice: bool) -> None:
        """The trial ended before a reason was given: say how, and offer what is left."""
        question = self.query_one("#question", Label)
        keys = self.query_one("#stop-keys", Label)
        self.query_one("#stop-needed", Label).update("")
        if outcome.trial_ids and not practice:
            self.mode, self.trial_id = "invalidate", outcome.trial_ids[0]
            question.update(
                f"{self.code}'s trial ended before it could be stopped: it is stored "
                f"completed (id {self.trial_id}). Mark it invalid instead? Why?"
            )
            keys.update("Enter: mark it invalid    Esc: keep it valid")
            return
        self.mode = "ended"
        how = (
            "stored completed (a practice trial: nothing to mark invalid)"
            if outcome.trial_ids
            else outcome.error or "not stored as completed"
        )
        question.update(f"{self.code}'s trial ended before it could be stopped: {how}.")
        self.query_one("#stop-reason", Input).display = False
        keys.update("Enter or Esc: close")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        reason = event.value.strip()
        if self.mode == "ended":
            self.dismiss(None)
        elif not reason:
            escape = "let it go on" if self.mode == "stop" else "keep it valid"
            self.query_one("#stop-needed", Label).update(NO_REASON.format(escape=escape))
        elif self.mode == "stop":
            self.dismiss(("stop", reason))
        else:
            self.dismiss(("invalidate", reason))

    def key_enter(self) -> None:
        """Enter with the field hidden (a trial that ended and cannot be marked) closes."""
        if self.mode == "ended":
            self.dismiss(None)

    def action_cancel(self) -> None:
        self.dismiss(None)
