"""The NASA-TLX screen: the form after a condition block, its validation, saving and editing.

Six ratings, 0-100 in steps of 5, each with its question and the anchors of the paper
form (Hart & Staveland 1988; NASA TLX manual); then the 15 pairwise comparisons in the
participant's own order (`study.protocol.tlx.pair_order`), each picked with the left and
right keys. Saving goes through `study.protocol.tlx.store_tlx`, the same checks as
`study tlx enter`: an off-scale rating or a missing choice is refused with a message
and nothing is stored. A block that already has its questionnaire opens filled in;
saving it again is an edit, which needs a reason and is written to the audit log
(shown below the form). Saving a stored questionnaire unchanged stores nothing; one
with ratings and no pairwise choices (a raw TLX, with no weighted score) is stored once
the operator has said so.

The participant, block and question lines are docked above the form, so they stay in
view while it scrolls; Tab and shift+Tab cycle through the form's own fields and its
button (and nothing else), each with the app's focus style.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from textual import events, on, work
from textual.actions import SkipAction
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.message import Message
from textual.widget import Widget
from textual.widgets import Button, Input, Label, Select, Static

from db.models.tlx import TLX_SUBSCALES
from study.errors import StudyInputError
from study.protocol.tlx import check_rating, load_tlx, pair_order, store_tlx, tlx_audit
from study.tui.char_count import CharCount
from study.tui.confirm import Confirm
from study.tui.db_errors import SafeWorkers
from study.tui.services import Roster, StudyServices

__all__ = ["TLX_SCALES", "PairChoice", "TlxPane"]

TLX_SCALES = {
    "mental": ("Mental demand", "How mentally demanding was the task?", "Very low", "Very high"),
    "physical": (
        "Physical demand",
        "How physically demanding was the task?",
        "Very low",
        "Very high",
    ),
    "temporal": (
        "Temporal demand",
        "How hurried or rushed was the pace of the task?",
        "Very low",
        "Very high",
    ),
    "performance": (
        "Performance",
        "How successful were you in accomplishing what you were asked to do?",
        "Perfect",
        "Failure",
    ),
    "effort": (
        "Effort",
        "How hard did you have to work to accomplish your level of performance?",
        "Very low",
        "Very high",
    ),
    "frustration": (
        "Frustration",
        "How insecure, discouraged, irritated, stressed, and annoyed were you?",
        "Very low",
        "Very high",
    ),
}
"""subscale -> (title, question, low anchor, high anchor), as on the NASA-TLX form."""


class PairChoice(Widget, can_focus=True):
    """One pairwise comparison: left/right picks the subscale that weighed more."""

    DEFAULT_CSS = """
    PairChoice { height: 1; padding: 0 1; }
    PairChoice:focus { background: $boost; text-style: bold; }
    """

    def __init__(self, number: int, pair: tuple[str, str], **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self.number, self.pair = number, pair
        self.choice: str | None = None

    # left and right pick on the pair that receives the key. As bindings they acted on
    # whichever pair had the focus once the key had passed up to the app, which, with
    # keys typed ahead, was a later pair; down and up: TlxPane.action_move_focus
    def key_left(self, event: events.Key) -> None:
        event.stop()
        self.action_pick(0)

    def key_right(self, event: events.Key) -> None:
        event.stop()
        self.action_pick(1)

    def action_pick(self, side: int) -> None:
        self.choice = self.pair[side]
        self.refresh()

    def render(self) -> str:
        if self.pair[0] not in TLX_SCALES:
            return f"{self.number:>2}. (pick a participant)"
        a, b = (TLX_SCALES[s][0] for s in self.pair)
        left = f"[reverse] {a} [/]" if self.choice == self.pair[0] else f" {a} "
        right = f"[reverse] {b} [/]" if self.choice == self.pair[1] else f" {b} "
        return f"{self.number:>2}. {left} or {right}"


def _same_answers(a: FormState, b: FormState) -> bool:
    """The same ratings (as numbers: `050` is 50) and the same choices."""
    ratings = [[_rating_value(v.strip()) for v in s.ratings] for s in (a, b)]
    return ratings[0] == ratings[1] and a.choices == b.choices


def _rating_value(text: str) -> object:
    """The typed rating as a number when it is one (check_rating then judges the scale)."""
    # lazy: study.protocol.csv_input (with pandas, pyarrow, numpy) costs 0.4 s at start-up
    from study.protocol.csv_input import whole_number

    value = whole_number(text)
    return text if value is None else value


Block = tuple[str, str, str]
"""(participant code, task, condition): the key of a questionnaire and of its draft."""


@dataclass(frozen=True)
class FormState:
    """What the form holds: the six ratings as typed, the 15 choices, the edit reason."""

    ratings: tuple[str, ...]
    choices: tuple[str | None, ...]
    reason: str


EMPTY = FormState(("",) * len(TLX_SUBSCALES), (None,) * 15, "")
"""The form with nothing in it."""


@dataclass(frozen=True)
class Draft:
    """Answers typed for a block and not saved, and the stored answers they were typed over
    (a draft over answers that have changed since is not restored)."""

    state: FormState
    over: FormState


class TlxPane(SafeWorkers, VerticalScroll, can_focus=False):
    """Enter or edit the questionnaire of one participant's block."""

    DEFAULT_CSS = """
    TlxPane { height: 1fr; }
    TlxPane .row { height: 1; }
    TlxPane .title { width: 17; }
    TlxPane .anchor { width: 10; color: $text-muted; }
    TlxPane .anchor-high { width: 10; color: $text-muted; }
    TlxPane Input { width: 8; }
    TlxPane #tlx-top Select { width: 16; }
    TlxPane #tlx-status { height: auto; }
    TlxPane #tlx-head { dock: top; height: 2; background: $surface; }
    TlxPane #question { height: 1; color: $text-muted; }
    TlxPane #reason-count { padding: 0 1; }
    TlxPane #audit { height: auto; color: $text-muted; }
    TlxPane #reason { width: 1fr; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("ctrl+s", "save", "Save TLX"),
        # up/down move between the fields (the page scrolls to the focused one) instead
        # of scrolling the page under the cursor. These four move the focus while the
        # app hands out the keys (priority), not once the key has reached the field: a
        # key typed right after one of them then goes to the new field, not the old one
        *(
            Binding(key, f"move_focus({step})", "Next field", show=False, priority=True)
            for key, step in (("down", 1), ("up", -1))
        ),
        *(
            Binding(key, f"cycle_focus({step})", "Next field", show=False, priority=True)
            for key, step in (("tab", 1), ("shift+tab", -1))
        ),
    ]

    @dataclass
    class Saved(Message):
        code: str
        task: str
        condition: str
        new: bool

    def __init__(self, services: StudyServices, **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self.services = services
        self.roster: Roster | None = None
        self.status = ""
        self.editing_id: int | None = None
        self._codes: list[str] = []
        self._blocks_code: str | None = None
        """The participant whose blocks the block list offers."""
        self._shown: Block | None = None
        """The block the form is for (participant, task, condition), loading or loaded."""
        self.loaded_block: Block | None = None
        """The block whose answers the form holds, once loaded (None while loading)."""
        self._baseline: FormState | None = None
        """The form as filled from the database (what counts as nothing typed)."""
        self.drafts: dict[Block, Draft] = {}
        """What was typed for a block and not saved, kept when another block is shown."""
        self.raw_only_ok: set[Block] = set()
        """Blocks whose raw-only save was confirmed (not asked again, say after a refusal)."""

    def compose(self) -> ComposeResult:
        # whose block and which question: docked, in view however far the form scrolls
        with Vertical(id="tlx-head"):
            with Horizontal(id="tlx-top", classes="row"):
                yield Label("Participant ")
                yield Select[str]([], id="tlx-participant", compact=True, prompt="pick")
                yield Label(" Block ")
                yield Select[str]([], id="tlx-block", compact=True, prompt="pick")
            yield Label("", id="question")
        for s in TLX_SUBSCALES:
            title, _, low, high = TLX_SCALES[s]
            with Horizontal(classes="row"):
                yield Label(title, classes="title")
                yield Label(f"{low:>9} ", classes="anchor")
                yield Input(id=f"rating-{s}", type="integer", placeholder="0-100", compact=True)
                yield Label(f" {high}", classes="anchor-high")
        yield Label("Which contributed more to the workload? (left / right)")
        for k in range(15):
            yield PairChoice(k + 1, ("", ""), id=f"pair-{k}")
        with Horizontal(classes="row"):
            yield Label("Reason ")
            yield Input(
                id="reason",
                placeholder="for an edit, or a block not run yet",
                compact=True,
            )
            yield CharCount(id="reason-count")
        yield Button("Save (ctrl+s)", id="save", compact=True)
        yield Static("", id="tlx-status")
        yield Static("", id="audit")

    # -- choosing the block ---------------------------------------------------------------
    #
    # One rule keeps what is typed with its own participant and block: the form changes
    # block only in `_switch`, which first keeps what was typed on the block it leaves
    # (compared with that block's own stored answers), then clears the form before the
    # next block's answers load. Nothing else writes a draft.

    def show(self, roster: Roster) -> None:
        self.roster = roster
        codes = [r["code"] for r in roster.participants]
        if codes != self._codes:
            self._codes = codes
            select = self.query_one("#tlx-participant", Select)
            select.set_options([(c, c) for c in codes])
            if self._blocks_code in codes:  # set_options cleared the shown participant
                select.value = self._blocks_code

    def open_block(self, code: str, task: str, condition: str) -> None:
        """Show the form for one block (from the run screen when a block ends)."""
        self._switch((code, task, condition))
        self._set_blocks(code)
        self.query_one("#tlx-participant", Select).value = code
        self.query_one("#tlx-block", Select).value = f"{task}/{condition}"
        # the first rating takes the keys at once (it took three Tabs to reach)
        self._to_first_rating()

    def _to_first_rating(self) -> None:
        """Focus the first rating with the form's top in view: whose block it is and the
        question (a form left scrolled to its Save button reopened with both hidden)."""
        self.scroll_home(animate=False, immediate=True)
        self.query_one(f"#rating-{TLX_SUBSCALES[0]}", Input).focus()

    def _set_blocks(self, code: str) -> None:
        """Offer `code`'s blocks and label the pairs in `code`'s own order."""
        if code == self._blocks_code:  # already shown (open_block, then Select.Changed)
            return
        self._blocks_code = code
        row = next(
            (r for r in (self.roster.participants if self.roster else ()) if r["code"] == code),
            None,
        )
        blocks = [f"{b['task']}/{b['condition']}" for b in row["blocks"]] if row else []
        self.query_one("#tlx-block", Select).set_options([(b, b) for b in blocks])
        seed = self.roster.seed if self.roster else 0
        for k, pair in enumerate(pair_order(seed, code)):
            widget = self.query_one(f"#pair-{k}", PairChoice)
            widget.pair = pair
            widget.refresh()

    @on(Select.Changed, "#tlx-participant")
    def _participant_changed(self, event: Select.Changed) -> None:
        event.stop()
        # a Changed that arrives after another pick (or open_block) is stale
        if event.value is Select.NULL or event.value != event.select.value:
            return
        code = str(event.value)
        if code == self._blocks_code:
            return
        kept = self._same_block_of(code)
        self._switch(kept)  # None: no block of the new participant picked yet
        self._set_blocks(code)
        if kept is not None:  # the block picked stands for the new participant too
            self.query_one("#tlx-block", Select).value = f"{kept[1]}/{kept[2]}"

    def _same_block_of(self, code: str) -> Block | None:
        """`code`'s block of the task and condition shown now, if `code` has one."""
        if self._shown is None or self.roster is None:
            return None
        _, task, condition = self._shown
        row = next((r for r in self.roster.participants if r["code"] == code), None)
        blocks = row["blocks"] if row else []
        if any(b["task"] == task and b["condition"] == condition for b in blocks):
            return (code, task, condition)
        return None

    @on(Select.Changed, "#tlx-block")
    def _block_changed(self, event: Select.Changed) -> None:
        event.stop()
        if event.value is Select.NULL or event.value != event.select.value:
            return
        if self._blocks_code is None:
            return
        task, condition = str(event.value).split("/")
        block = (self._blocks_code, task, condition)
        if block != self._shown:  # open_block has already switched to the block it picks
            self._switch(block)

    def _switch(self, block: Block | None) -> None:
        """Show `block` (None: no block): keep the draft of the one left, clear, load."""
        self._keep_draft()
        self._shown, self.loaded_block, self._baseline = block, None, None
        self.editing_id = None
        self._apply(EMPTY)
        self.query_one("#audit", Static).update("")
        if block is None:
            self._set_status("pick a block")
        else:
            self._set_status("loading")
            self._load_worker(block, "")

    def action_move_focus(self, step: int) -> None:
        """The next (1) or previous (-1) field, at once. In a participant or block list
        the keys are the list's own (they move in its open menu)."""
        focused = self.screen.focused
        if focused is None or any(isinstance(w, Select) for w in (focused, *focused.ancestors)):
            raise SkipAction()
        self.action_cycle_focus(step)

    def action_cycle_focus(self, step: int) -> None:
        """Tab / shift+Tab: the next or previous of the form's own fields and its
        button, round from the last to the first (never the tab bar, nor a stop that
        shows no focus)."""
        chain = [w for w in self.screen.focus_chain if self in w.ancestors]
        if not chain:
            raise SkipAction()
        focused = self.screen.focused
        at = chain.index(focused) if focused in chain else (-1 if step > 0 else 0)
        # at once, not after the keys already queued (`focus` waits for them): the next
        # key typed goes to the field this one moved to
        self.screen.set_focus(chain[(at + step) % len(chain)])

    def focus_first(self) -> None:
        """F4: the first rating of the block shown; with none shown, the questionnaire
        due (of the participant picked on the run screen first), else the participant
        list."""
        if self._shown is None:
            due = self._due_block()
            if due is not None:
                self.open_block(*due)
                return
        if self._shown is not None:
            self._to_first_rating()
        else:
            self.query_one("#tlx-participant", Select).focus()

    def _due_block(self) -> Block | None:
        due = self.roster.tlx_due() if self.roster is not None else []
        if not due:
            return None
        runs = self.app.query("#run-pane")  # the participant picked there comes first
        picked = getattr(runs.first(), "code", None) if runs else None
        return next((b for b in due if b[0] == picked), due[0])

    def on_descendant_focus(self, event: events.DescendantFocus) -> None:
        """The question of the focused rating above the form, and the focused field in
        view (shift+tab onto Save scrolled nothing). Of the field focused now, not of
        the event's: these events can arrive out of order (the participant list's, from
        when F4 focused it, after the first rating's), which blanked the question."""
        widget = self.screen.focused
        if widget is None or self not in widget.ancestors:
            return
        text = ""
        if widget.id and widget.id.startswith("rating-"):
            text = TLX_SCALES[widget.id.removeprefix("rating-")][1]
        elif isinstance(widget, PairChoice):
            text = "Which of the two contributed more to your workload? left / right"
        self.query_one("#question", Label).update(text)
        widget.scroll_visible(animate=False)

    @on(Input.Changed, "#reason")
    def _reason_typed(self, event: Input.Changed) -> None:
        self.query_one("#reason-count", CharCount).count(event.value)

    @on(Input.Changed)
    def _rating_typed(self, event: Input.Changed) -> None:
        if event.input.id and event.input.id.startswith("rating-"):
            s = event.input.id.removeprefix("rating-")
            try:
                check_rating(s, _rating_value(event.value))
                event.input.remove_class("-invalid")
            except StudyInputError:
                event.input.set_class(bool(event.value), "-invalid")

    @work(thread=True, exclusive=True, group="tlx-load", exit_on_error=False)
    def _load_worker(self, block: Block, note: str) -> None:

        response = load_tlx(self.services.engine, *block)
        audit = tlx_audit(self.services.engine, response.id) if response is not None else []
        self.app.call_from_thread(self._fill, block, response, audit, note)

    def _fill(self, block: Block, response, audit, note: str) -> None:
        if block != self._shown:  # another block was picked while this one loaded
            return
        typed_meanwhile = self.form_state()
        self.editing_id = None if response is None else response.id
        stored = (
            EMPTY
            if response is None
            else FormState(
                tuple(str(getattr(response, s)) for s in TLX_SUBSCALES),
                tuple([c for _, _, c in (response.pairwise or [])] + [None] * 15)[:15],
                "",
            )
        )
        self._apply(stored)
        self._baseline, self.loaded_block = stored, block
        state = "stored: editing it needs a reason" if response is not None else "new"
        draft = self.drafts.get(block)
        if draft is not None and draft.over != stored:
            # typed over answers that have changed since (stored elsewhere): the stored
            # ones stand, and the operator is told rather than shown a stale draft
            del self.drafts[block]
            state += "; answers typed here earlier were not restored: stored meanwhile"
        elif draft is not None and response is None:
            self._apply(draft.state)
            state = "draft restored (typed earlier, not saved yet): ctrl+s saves it"
        elif draft is not None:
            self._apply(draft.state)
            state = "edit restored (typed earlier, not saved yet): ctrl+s with a reason saves it"
        elif response is None and typed_meanwhile != EMPTY:
            self._apply(typed_meanwhile)  # keys pressed while it loaded stay
        self._set_status(note or state, notify=bool(note))
        lines = [
            f"{a.at:%Y-%m-%d %H:%M} {a.field}: {a.old_value} -> {a.new_value} ({a.reason})"
            for a in audit[-5:]
        ]
        self.query_one("#audit", Static).update("\n".join(["audit log:", *lines]) if lines else "")

    # -- drafts ---------------------------------------------------------------------------

    def form_state(self) -> FormState:
        ratings = tuple(self.query_one(f"#rating-{s}", Input).value for s in TLX_SUBSCALES)
        choices = tuple(self.query_one(f"#pair-{k}", PairChoice).choice for k in range(15))
        return FormState(ratings, choices, self.query_one("#reason", Input).value)

    def _apply(self, state: FormState) -> None:
        for s, value in zip(TLX_SUBSCALES, state.ratings, strict=True):
            self.query_one(f"#rating-{s}", Input).value = value
        for k, choice in enumerate(state.choices):
            widget = self.query_one(f"#pair-{k}", PairChoice)
            widget.choice = choice
            widget.refresh()
        self.query_one("#reason", Input).value = state.reason

    def is_dirty(self) -> bool:
        """Something typed on the shown block and not saved."""
        return self.loaded_block is not None and self.form_state() != self._baseline

    def unsaved(self) -> list[Block]:
        """The blocks with answers typed and not saved (the shown one and the drafts)."""
        self._keep_draft()
        return list(self.drafts)

    def _keep_draft(self) -> None:
        """Keep (or drop) the draft of the loaded block, while the form still holds it."""
        block, baseline = self.loaded_block, self._baseline
        if block is None or baseline is None:
            return
        state = self.form_state()
        if state != baseline:
            self.drafts[block] = Draft(state, baseline)
        else:
            self.drafts.pop(block, None)

    def worker_failed(self, group: str, line: str) -> None:
        # the form is left as it is: what was typed stays for the next ctrl+s
        self._set_status(f"refused: {line}; the form keeps what was typed", notify=True)

    def _set_status(self, text: str, notify: bool = False) -> None:
        self.status = text
        self.query_one("#tlx-status", Static).update(text)
        if notify:  # the status line may be scrolled out of view at 80 x 24
            refused = text.startswith("refused")
            self.app.notify(text, severity="error" if refused else "information")

    # -- saving ---------------------------------------------------------------------------

    @on(Button.Pressed, "#save")
    def _save_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.action_save()

    def action_save(self) -> None:
        block = self.loaded_block
        if block is None:
            why = (
                "pick a participant and a block first"
                if self._shown is None
                else ("the block's answers are still loading")
            )
            self._set_status(f"refused: {why}", notify=True)
            return
        state = self.form_state()
        if self.editing_id is not None and self._baseline is not None:
            if _same_answers(state, self._baseline):  # nothing to store, nothing to log
                self._set_status(f"{block[0]} {block[1]}/{block[2]}: unchanged", notify=True)
                return
        ratings = {s: _rating_value(v) for s, v in zip(TLX_SUBSCALES, state.ratings, strict=True)}
        reason = state.reason.strip() or None
        errors = self._errors(ratings, state.choices, reason)
        if errors:  # every error at once, not only the first
            self._set_status("refused: " + "; ".join(errors), notify=True)
            return
        picks = None if state.choices[0] is None else [str(c) for c in state.choices]
        stored_raw = self._baseline is not None and self._baseline.choices[0] is None
        asked = block in self.raw_only_ok or (self.editing_id is not None and stored_raw)
        if picks is None and not asked:
            self._ask_raw_only(block, ratings, reason)
            return
        self._store(block, ratings, picks, reason)

    def _ask_raw_only(self, block: Block, ratings: dict[str, object], reason: str | None) -> None:
        """Ratings without the pairwise choices have no weighted score: asked once."""

        def answered(yes: bool | None) -> None:
            if yes and self.loaded_block == block:
                self.raw_only_ok.add(block)
                self._store(block, ratings, None, reason)
            elif not yes:
                self._set_status("not stored: pick the 15 pairwise choices, or store the raw score")

        self.app.push_screen(
            Confirm(
                f"{block[0]} {block[1]}/{block[2]}: no pairwise choices: store the raw "
                "score only? (no weighted score then)"
            ),
            answered,
        )

    def _errors(
        self, ratings: dict[str, object], choices: tuple[str | None, ...], reason: str | None
    ) -> list[str]:
        """What is wrong with the form, one line each (the checks of `study tlx enter`)."""
        errors = []
        for s, v in ratings.items():
            try:
                check_rating(s, v)
            except StudyInputError as exc:
                errors.append(str(exc))
        missing = [k + 1 for k, c in enumerate(choices) if c is None]
        if missing and len(missing) < 15:
            errors.append(
                f"pairwise choices {', '.join(map(str, missing))} are missing; expected "
                "all 15 (or none, for a raw TLX only)"
            )
        if self.editing_id is not None and reason is None:
            errors.append("this block's TLX is stored; an edit needs a reason")
        return errors

    @work(thread=True, exclusive=True, group="tlx-store", exit_on_error=False)
    def _store(self, block: Block, ratings, chosen, reason) -> None:

        try:
            observer = self.services.lsl_observer()
        except Exception:  # the run screen says why; the answers are stored regardless
            observer = None
        try:
            _, new = store_tlx(
                self.services.engine, *block, ratings, chosen, reason, observer=observer
            )
        except ValueError as exc:
            self.app.call_from_thread(self._set_status, f"refused: {exc}", True)
            return
        self.post_message(self.Saved(*block, new))

    @on(Saved)
    def _saved(self, event: Saved) -> None:
        block = (event.code, event.task, event.condition)
        self.drafts.pop(block, None)  # stored: no longer a draft, wherever the form is
        verb = "stored" if event.new else "updated (changes in the audit log)"
        note = f"{event.code} {event.task}/{event.condition}: {verb}"
        if block == self._shown:  # reload what is now stored (the form stays meanwhile)
            self.loaded_block, self._baseline = None, None
            self._load_worker(block, note)
        else:
            self.app.notify(note)
