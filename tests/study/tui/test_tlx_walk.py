"""A seeded random walk of a lab day through the app, checked against a model after every step.

Each example enrols participants, runs blocks with simulated participants (as fast as they
go), types NASA-TLX ratings and pairwise choices by key (one at a time, or the whole form
as one burst typed ahead), switches participant and block
(by the lists and as the run screen does when a block ends), saves, and quits and
restarts the app over the same database. The model holds what was typed on each block
and what was stored; after every step:

- every stored questionnaire equals what was typed for that participant and block, and
  nothing is stored for a block never saved;
- the form shows exactly what was typed (or stored) for its own block, so a draft
  restores only on its own participant and block, and a stored block is never a draft;
- the quit warning lists exactly the blocks with unsaved answers.

A seeded walk rather than hypothesis' RuleBasedStateMachine: every step needs the app's
event loop (`await pilot.press`), which hypothesis' synchronous rules do not run in, and
a failing seed is replayed exactly with `-k "walk[SEED]"`.

`STUDY_TUI_WALK_EXAMPLES` (default 6) and `STUDY_TUI_WALK_STEPS` (default 50) make the
walk longer for a nightly run.
"""

from __future__ import annotations

import os
import random
from dataclasses import dataclass, field

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session
from textual.widgets import Input, Select

from db.models.study import Participant
from db.models.tlx import TLX_SUBSCALES, TlxResponse
from study.protocol.tlx import pair_order
from study.tui.confirm import Confirm
from study.tui.run_pane import RunPane
from study.tui.tlx_pane import PairChoice, TlxPane
from tests.study.tui.conftest import loaded, wait_for

EXAMPLES = int(os.environ.get("STUDY_TUI_WALK_EXAMPLES", "6"))
STEPS = int(os.environ.get("STUDY_TUI_WALK_STEPS", "50"))
SEED = 3  # conftest.DESIGN's study seed: the pairs' order follows from it
TASK_BLOCKS = ("lcca/VO", "lcca/HV")
GROUP_TARGET = 2  # conftest.DESIGN: novice 2, expert 2

Block = tuple[str, str, str]
Form = tuple[tuple[str, ...], tuple[str | None, ...], str]
EMPTY: Form = (("",) * 6, (None,) * 15, "")


def _valid(value: str) -> bool:
    return value.isdigit() and int(value) % 5 == 0 and 0 <= int(value) <= 100


@dataclass
class Model:
    """What the operator did: typed answers per block, stored answers, runs, the form."""

    codes: list[str] = field(default_factory=lambda: ["P001", "P002"])
    groups: dict[str, int] = field(default_factory=lambda: {"novice": 1, "expert": 1})
    run: set[Block] = field(default_factory=set)
    stored: dict[Block, Form] = field(default_factory=dict)
    typed: dict[Block, Form] = field(default_factory=dict)
    shown: Block | None = None
    on_participant: str | None = None
    raw_only_ok: set[Block] = field(default_factory=set)
    """Blocks whose raw-only save was confirmed since the app started."""

    def stored_form(self, block: Block) -> Form:
        return self.stored.get(block, EMPTY)

    def form(self, block: Block | None) -> Form:
        if block is None:
            return EMPTY
        return self.typed.get(block, self.stored_form(block))

    def unsaved(self) -> set[Block]:
        return {b for b, f in self.typed.items() if f != self.stored_form(b)}

    def refusals(self, block: Block) -> bool:
        """True if saving the form of `block` must be refused."""
        ratings, choices, reason = self.form(block)
        partial = any(c is None for c in choices) and any(c is not None for c in choices)
        needs_reason = block in self.stored or block not in self.run
        return (
            not all(_valid(r) for r in ratings) or partial or (needs_reason and not reason.strip())
        )


class Walk:
    def __init__(self, rng: random.Random, engine, model: Model) -> None:
        self.rng, self.engine, self.model = rng, engine, model
        self.pilot = None

    @property
    def app(self):
        return self.pilot.app

    @property
    def pane(self) -> TlxPane:
        return self.app.query_one(TlxPane)

    async def to_form(self) -> None:
        """F4; with no block shown it opens the questionnaire due (the run screen's
        participant's first), as the roster the form holds says."""
        if self.app.query_one("#tabs").active == "tlx":
            return
        due = self.pane.roster.tlx_due() if self.pane.roster is not None else []
        picked = self.app.query_one("#run-pane").code
        await self.pilot.press("f4")
        if self.model.shown is None and due:
            block = next((b for b in due if b[0] == picked), due[0])
            self.model.shown, self.model.on_participant = block, block[0]
            await self.settled()

    async def settled(self) -> None:
        """Wait until the form holds the block the model says it shows."""
        want = self.model.shown
        await wait_for(
            self.pilot,
            lambda: (
                self.pane.loaded_block == want and (want is not None or self.pane._shown is None)
            ),
            20,
        )
        await self.pilot.pause()

    # -- the steps --------------------------------------------------------------------

    async def enrol(self) -> None:
        await self.pilot.press("f2")
        await self.pilot.press("ctrl+a")  # the first group (novice) is preselected
        if self.model.groups["novice"] >= GROUP_TARGET:
            await wait_for(self.pilot, lambda: isinstance(self.app.screen, Confirm), 10)
            await self.pilot.press("y")
        code = f"P{len(self.model.codes) + 1:03d}"
        self.model.codes.append(code)
        self.model.groups["novice"] += 1
        await wait_for(self.pilot, lambda: code in (self.pane._codes or []), 20)
        await self.to_form()

    async def run_block(self) -> None:
        """The next trial of a participant with one, by the run screen (s, confirmations)."""
        m = self.model
        roster = self.app.roster
        ready = [
            c
            for c in m.codes
            if roster.next_trial(c) is not None and not [b for b in roster.tlx_due() if b[0] == c]
        ]
        if not ready:
            return
        code = self.rng.choice(ready)
        nxt = roster.next_trial(code)
        block = (code, nxt.task, nxt.condition)
        await self.pilot.press("f3")
        run = self.app.query_one(RunPane)
        run.select_participant(code)
        await self.pilot.pause()
        run.last_outcome = ""
        await self.pilot.press("s")

        def started() -> bool:
            return run.run is not None or run.last_outcome != ""

        while not started():  # the checklist or the break is asked first
            await wait_for(
                self.pilot, lambda: isinstance(self.app.screen, Confirm) or started(), 20
            )
            if isinstance(self.app.screen, Confirm):
                await self.pilot.press("y")
                await self.pilot.pause()
        await wait_for(self.pilot, lambda: run.run is None and run.last_outcome != "", 120)
        assert run.status == "completed", run.last_outcome
        m.run.add(block)
        # one trial a block: the block is done and its questionnaire opens (unless stored)
        if block not in m.stored:
            m.shown = block
            m.on_participant = code
            await wait_for(self.pilot, lambda: self.pane._shown == block, 20)
        await self.to_form()
        await self.settled()

    async def open_block(self) -> None:
        """As the run screen opens a finished block's questionnaire."""
        code = self.rng.choice(self.model.codes)
        task, condition = self.rng.choice(TASK_BLOCKS).split("/")
        await self.to_form()
        self.pane.open_block(code, task, condition)
        self.model.shown, self.model.on_participant = (code, task, condition), code
        await self.settled()

    async def pick_participant(self) -> None:
        """The participant list: the block shown stays, now the new participant's; with
        none shown, the form is left empty until a block is picked."""
        code = self.rng.choice(self.model.codes)
        await self.to_form()
        self.app.query_one("#tlx-participant", Select).value = code
        if code != self.model.on_participant:  # the block picked stays: they all have it
            shown = self.model.shown
            self.model.shown = None if shown is None else (code, *shown[1:])
            self.model.on_participant = code
        await self.pilot.pause()
        await self.settled()

    async def pick_block(self) -> None:
        """The block list of the participant picked."""
        code = self.model.on_participant
        if code is None:
            return
        block = self.rng.choice(TASK_BLOCKS)
        await self.to_form()
        self.app.query_one("#tlx-block", Select).value = block
        self.model.shown = (code, *block.split("/"))
        await self.settled()

    def _typed(self, ratings=None, choices=None, reason=None) -> None:
        m = self.model
        r, c, why = m.form(m.shown)
        m.typed[m.shown] = (ratings or r, choices or c, why if reason is None else reason)

    async def type_rating(self) -> None:
        if self.model.shown is None:
            return
        await self.to_form()
        k = self.rng.randrange(6)
        value = str(self.rng.choice([*range(0, 101, 5), 103, 52, 7]))
        field_ = self.app.query_one(f"#rating-{TLX_SUBSCALES[k]}", Input)
        field_.focus()
        field_.cursor_position = len(field_.value)
        await self.pilot.press("ctrl+u", *value)
        ratings = list(self.model.form(self.model.shown)[0])
        ratings[k] = value
        self._typed(ratings=tuple(ratings))

    async def pick_pair(self) -> None:
        if self.model.shown is None:
            return
        await self.to_form()
        code = self.model.shown[0]
        choices = list(self.model.form(self.model.shown)[1])
        if self.rng.random() < 0.2:  # the whole list at once, by the pairs' own action
            for k in range(15):
                side = self.rng.randrange(2)
                self.app.query_one(f"#pair-{k}", PairChoice).action_pick(side)
                choices[k] = pair_order(SEED, code)[k][side]
        else:  # one pair by key
            k, side = self.rng.randrange(15), self.rng.randrange(2)
            self.app.query_one(f"#pair-{k}", PairChoice).focus()
            await self.pilot.press("left" if side == 0 else "right")
            choices[k] = pair_order(SEED, code)[k][side]
        self._typed(choices=tuple(choices))

    async def type_ahead(self) -> None:
        """The whole form as one burst of keys, posted before the app handles the first
        (a quick operator, or a busy app): six ratings with down between them, then a
        side of each pair with down between them."""
        from textual import events

        if self.model.shown is None:
            return
        await self.to_form()
        first = self.app.query_one(f"#rating-{TLX_SUBSCALES[0]}", Input)
        first.focus()
        await self.pilot.pause()
        # its text selected, so the burst replaces it (focusing selects it, but the field
        # may have the focus already, as a form opens on it)
        first.select_all()
        await wait_for(self.pilot, lambda: first.selected_text == first.value, 10)
        code = self.model.shown[0]
        ratings = [str(self.rng.choice([*range(0, 101, 5), 103])) for _ in TLX_SUBSCALES]
        sides = [self.rng.randrange(2) for _ in range(15)]
        keys: list[str] = []
        for value in ratings:
            keys += [*value, "down"]
        for side in sides:
            keys += ["left" if side == 0 else "right", "down"]
        for key in keys:
            self.app.post_message(events.Key(key, key if len(key) == 1 else None))
        await wait_for(self.pilot, lambda: self.app.focused is self.app.query_one("#reason"), 20)
        await self.pilot.pause()
        order = pair_order(SEED, code)
        choices = tuple(order[k][side] for k, side in enumerate(sides))
        self._typed(ratings=tuple(ratings), choices=choices)

    async def type_reason(self) -> None:
        if self.model.shown is None:
            return
        await self.to_form()
        field_ = self.app.query_one("#reason", Input)
        field_.focus()
        field_.cursor_position = len(field_.value)
        await self.pilot.press("ctrl+u", *"typo")
        self._typed(reason="typo")

    async def save(self) -> None:
        m = self.model
        await self.to_form()
        before = self.pane.status
        await self.pilot.press("ctrl+s")
        if m.shown is None:
            assert self.pane.status.startswith("refused: pick a participant")
            return
        code, task, condition = m.shown
        ratings, choices, _ = m.form(m.shown)
        if m.shown in m.stored and m.stored[m.shown][:2] == (ratings, choices):
            # nothing changed: said so, nothing stored (a reason or none)
            unchanged = f"{code} {task}/{condition}: unchanged"
            await wait_for(self.pilot, lambda: self.pane.status == unchanged, 10)
            return
        if m.refusals(m.shown):
            assert self.pane.status.startswith("refused"), (m.form(m.shown), self.pane.status)
            return
        stored_raw = m.shown in m.stored and m.stored[m.shown][1][0] is None
        asked = stored_raw or m.shown in m.raw_only_ok
        if choices[0] is None and not asked:  # ratings only: asked once first
            await wait_for(self.pilot, lambda: isinstance(self.app.screen, Confirm), 10)
            question = str(self.app.screen.query_one("#question").render())
            assert "no pairwise choices: store the raw score only?" in question
            if self.rng.random() < 0.3:
                await self.pilot.press("n")
                await wait_for(self.pilot, lambda: self.pane.status.startswith("not stored"))
                return
            await self.pilot.press("y")
            m.raw_only_ok.add(m.shown)
        done = (f"{code} {task}/{condition}: stored", f"{code} {task}/{condition}: updated")
        await wait_for(
            self.pilot,
            lambda: self.pane.status.startswith(done) and self.pane.loaded_block == m.shown,
            20,
        )
        assert self.pane.status != before or before.startswith(done)
        m.stored[m.shown] = (ratings, choices, "")
        m.typed.pop(m.shown)

    async def quit(self) -> bool:
        """ctrl+q: the warning lists exactly the unsaved blocks; y quits (the drafts go)."""
        m = self.model
        await self.pilot.press("ctrl+q")
        unsaved = m.unsaved()
        if not unsaved:
            await wait_for(self.pilot, lambda: not self.app.is_running, 20)
            m.shown = m.on_participant = None
            m.raw_only_ok.clear()
            return True
        await wait_for(self.pilot, lambda: isinstance(self.app.screen, Confirm), 10)
        question = str(self.app.screen.query_one("#question").render())
        listed = question.split("(")[1].split(")")[0].split(", ")
        assert sorted(listed) == sorted(f"{c} {t}/{k}" for c, t, k in unsaved), question
        if self.rng.random() < 0.3:
            await self.pilot.press("n")
            await self.pilot.pause()
            return False
        await self.pilot.press("y")
        await wait_for(self.pilot, lambda: not self.app.is_running, 20)
        m.typed.clear()
        m.shown = m.on_participant = None
        m.raw_only_ok.clear()
        return True

    # -- the invariants ---------------------------------------------------------------

    def check(self) -> None:
        m = self.model
        with Session(self.engine) as session:
            rows = session.execute(
                select(Participant.code, TlxResponse).join(TlxResponse.participant)
            ).all()
            stored = {
                (code, r.task, r.condition): (
                    tuple(str(getattr(r, s)) for s in TLX_SUBSCALES),
                    tuple(c for _, _, c in r.pairwise) if r.pairwise else (None,) * 15,
                    "",
                )
                for code, r in rows
            }
        assert stored == m.stored
        if self.app.is_running:
            form = self.pane.form_state()
            assert (form.ratings, form.choices, form.reason) == m.form(m.shown), m.shown
            if self.pane.status.startswith("draft restored"):
                assert m.shown not in m.stored
                assert m.form(m.shown) != EMPTY
            assert set(self.pane.unsaved()) == m.unsaved()


@pytest.fixture(scope="module")
def shared_estimator():
    """The shipped estimator, loaded once for every example (each restart builds an app)."""
    from study.protocol.default_estimator import load_estimator

    estimator = load_estimator()
    return lambda: estimator


STEP_WEIGHTS = {
    "enrol": 1,
    "run_block": 2,
    "open_block": 5,
    "pick_participant": 4,
    "pick_block": 4,
    "type_rating": 16,
    "pick_pair": 8,
    "type_ahead": 2,
    "type_reason": 2,
    "save": 6,
    "quit": 2,
}


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(EXAMPLES))
async def test_walk(seed: int, make_test_app, study_engine, shared_estimator) -> None:
    rng = random.Random(seed)
    walk = Walk(rng, study_engine, Model())
    steps, names = 0, list(STEP_WEIGHTS)
    while steps < STEPS:
        app = make_test_app(load_estimator=shared_estimator, simulated_pace=None)
        async with app.run_test(size=(80, 24)) as pilot:
            walk.pilot = pilot
            await loaded(pilot)
            await walk.to_form()
            while steps < STEPS:
                name = rng.choices(names, weights=list(STEP_WEIGHTS.values()))[0]
                if walk.model.groups["novice"] >= 4 and name == "enrol":
                    continue
                steps += 1
                left = await getattr(walk, name)()
                walk.check()
                if left:
                    break
            if app.is_running:
                walk.model.typed.clear()
                await pilot.press("ctrl+q")
                if isinstance(app.screen, Confirm):
                    await pilot.press("y")
    walk.check()
