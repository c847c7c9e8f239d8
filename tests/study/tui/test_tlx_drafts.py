"""What is typed on the NASA-TLX form stays with its own participant and block.

A draft is keyed by (participant, task, condition) and holds the six ratings and the 15
pairwise choices; storing the questionnaire clears it; switching participant or block
shows that block's own stored answers, its own draft, or an empty form.
"""

from __future__ import annotations

from textual.widgets import Input, Select

from db.models.tlx import TLX_SUBSCALES
from study.protocol.tlx import load_tlx
from study.tui.confirm import Confirm
from study.tui.tlx_pane import PairChoice, TlxPane
from tests.study.tui.conftest import complete_block, loaded, wait_for

P001_RATINGS = ("40", "35", "45", "30", "60", "25")
P002_RATINGS = ("10", "20", "30", "40", "50", "60")


async def _form(pilot) -> TlxPane:
    await loaded(pilot)
    await pilot.press("f4")
    return pilot.app.query_one(TlxPane)


async def _shown(pilot, pane: TlxPane, code: str, task: str, condition: str) -> None:
    """Wait until the form shows (and has loaded) the block."""
    await wait_for(pilot, lambda: pane.loaded_block == (code, task, condition), 10)


async def _type(pilot, ratings: tuple[str, ...], sides: list[int] | None = None) -> None:
    """Type the ratings key by key, then pick the pairs with left/right."""
    app = pilot.app
    for s, value in zip(TLX_SUBSCALES, ratings, strict=True):
        field = app.query_one(f"#rating-{s}", Input)
        field.focus()
        await pilot.press("ctrl+a", "backspace", *value) if field.value else None
        if not field.value:
            await pilot.press(*value)
    for k, side in enumerate(sides or []):
        app.query_one(f"#pair-{k}", PairChoice).focus()
        await pilot.press("left" if side == 0 else "right")


def _ratings(app) -> tuple[str, ...]:
    return tuple(app.query_one(f"#rating-{s}", Input).value for s in TLX_SUBSCALES)


def _choices(app) -> list[str | None]:
    return [app.query_one(f"#pair-{k}", PairChoice).choice for k in range(15)]


SIDES = [k % 2 for k in range(15)]


async def test_saved_ratings_are_not_carried_to_the_next_participant(
    make_test_app, study_engine
) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    complete_block(study_engine, "P002", "lcca", "HV")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _form(pilot)
        pane.open_block("P001", "lcca", "VO")
        await _shown(pilot, pane, "P001", "lcca", "VO")
        await _type(pilot, P001_RATINGS, SIDES)
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: pane.status == "P001 lcca/VO: stored", 10)
        # the next participant's block opens (as when their block ends): an empty form
        pane.open_block("P002", "lcca", "HV")
        await _shown(pilot, pane, "P002", "lcca", "HV")
        await pilot.pause(0.2)  # the participant Select's own Changed message arrives
        assert _ratings(app) == ("",) * 6
        assert _choices(app) == [None] * 15
        assert pane.status == "new"
        # merely picking another participant on the list shows their (empty) form of the
        # same block
        pane.open_block("P001", "lcca", "VO")
        await _shown(pilot, pane, "P001", "lcca", "VO")
        assert _ratings(app) == P001_RATINGS
        app.query_one("#tlx-participant", Select).value = "P002"
        await _shown(pilot, pane, "P002", "lcca", "VO")
        await pilot.pause(0.2)
        assert _ratings(app) == ("",) * 6
        assert _choices(app) == [None] * 15
    stored = load_tlx(study_engine, "P001", "lcca", "VO")
    assert tuple(str(getattr(stored, s)) for s in TLX_SUBSCALES) == P001_RATINGS
    assert load_tlx(study_engine, "P002", "lcca", "HV") is None


async def test_switching_participant_and_back_keeps_the_drafts_choices(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _form(pilot)
        pane.open_block("P001", "lcca", "VO")
        await _shown(pilot, pane, "P001", "lcca", "VO")
        await _type(pilot, P001_RATINGS, SIDES)
        typed = _choices(app)
        assert None not in typed
        # to P002 by the list (the same block, theirs), then back to P001 by the list
        app.query_one("#tlx-participant", Select).value = "P002"
        await _shown(pilot, pane, "P002", "lcca", "VO")
        await pilot.pause(0.1)
        assert app.query_one("#tlx-block", Select).value == "lcca/VO"
        assert _ratings(app) == ("",) * 6
        assert _choices(app) == [None] * 15
        app.query_one("#tlx-participant", Select).value = "P001"
        await _shown(pilot, pane, "P001", "lcca", "VO")
        await pilot.pause(0.1)
        assert pane.status.startswith("draft restored")
        assert _ratings(app) == P001_RATINGS
        assert _choices(app) == typed
        assert pane.unsaved() == [("P001", "lcca", "VO")]


async def test_quit_warns_only_about_drafts_that_exist(make_test_app, study_engine) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    complete_block(study_engine, "P002", "lcca", "HV")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _form(pilot)
        for code, condition, ratings in (
            ("P001", "VO", P001_RATINGS),
            ("P002", "HV", P002_RATINGS),
        ):
            pane.open_block(code, "lcca", condition)
            await _shown(pilot, pane, code, "lcca", condition)
            await _type(pilot, ratings, SIDES)
            await pilot.press("ctrl+s")
            await wait_for(
                pilot, lambda c=code, k=condition: pane.status == f"{c} lcca/{k}: stored", 10
            )
        # back on the first, stored block: it is no draft
        pane.open_block("P001", "lcca", "VO")
        await _shown(pilot, pane, "P001", "lcca", "VO")
        await pilot.pause(0.2)
        assert pane.status.startswith("stored")
        assert pane.unsaved() == []
        await pilot.press("ctrl+q")
        await pilot.pause(0.2)
        assert not isinstance(app.screen, Confirm)
    assert not app.is_running
